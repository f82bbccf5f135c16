//! Any bytes as INRIA cameras.json: cameras with finite poses and positive intrinsics, or
//! a clear error; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(cams) = unseen::camera::inria::parse_cameras_json(data, std::path::Path::new("fuzz.json")) {
        for c in cams {
            assert!(c.width > 0 && c.height > 0);
            assert!(c.fx.is_finite() && c.fx > 0.0 && c.fy.is_finite() && c.fy > 0.0);
        }
    }
});
