//! Any bytes split into cameras.bin / images.bin / points3D.bin: Ok or an error, no panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let a = data[0] as usize % data.len();
    let b = a + (data[1] as usize % (data.len() - a));
    let _ = unseen::camera::colmap::parse_colmap_bin(&data[..a], &data[a..b], &data[b..]);
});
