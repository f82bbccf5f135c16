//! Poses: when two cameras are the same view, and which training views are closest to a
//! camera (SPEC.md §20.2).

use crate::camera::Camera;
use crate::dataset::Dataset;

/// Whether two cameras have the same pose (centre within 1e-9, rotation entries within
/// 1e-9): what "the same view" means for candidates (SPEC.md §20.2).
pub fn same_pose(a: &Camera, b: &Camera) -> bool {
    (a.center - b.center).length() < 1e-9
        && a.world_from_camera_rotation
            .abs_diff_eq(b.world_from_camera_rotation, 1e-9)
}

/// The pose distance used to pick "the closest training cameras" (SPEC.md §20.2):
/// centre distance in units of the scene extent plus `1 − cos` of the angle between the
/// viewing directions, so a camera at the same place looking the other way is far.
pub fn pose_distance(a: &Camera, b: &Camera, extent: f64) -> f64 {
    let za = a.world_from_camera_rotation.z_axis;
    let zb = b.world_from_camera_rotation.z_axis;
    (a.center - b.center).length() / extent.max(1e-12) + (1.0 - za.dot(zb))
}

/// The `k` training views of `data` closest to `cam` by [`pose_distance`] (ties: the
/// lower view index), nearest first.
pub fn nearest_training(data: &Dataset, cam: &Camera, k: usize) -> Vec<usize> {
    let extent = data.scene_extent() as f64;
    let mut d: Vec<(f64, usize)> = data
        .train
        .iter()
        .map(|&i| (pose_distance(&data.views[i].camera, cam, extent), i))
        .collect();
    d.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    d.into_iter().take(k).map(|(_, i)| i).collect()
}
