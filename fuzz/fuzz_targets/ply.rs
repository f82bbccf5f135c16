//! Any bytes: the PLY reader returns Ok or a clear error, never panics or over-allocates.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = unseen::gaussian::ply::parse_ply(data, std::path::Path::new("fuzz.ply"));
});
