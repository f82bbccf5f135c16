//! Any bytes: the point-cloud PLY reader returns Ok or a clear error, never panics or
//! over-allocates; every point it returns is finite.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(pc) = unseen::gaussian::ply::parse_point_cloud(data, std::path::Path::new("fuzz.ply")) {
        assert_eq!(pc.xyz.len(), pc.rgb.len());
        assert!(pc.xyz.iter().flatten().all(|v| v.is_finite()));
    }
});
