//! Initial extrinsics: a maximum spanning tree over camera pairs weighted by the number of views they
//! share, relative poses averaged over those views and chained from the root camera.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// One edge of the spanning tree.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TreeEdge {
    /// Camera closer to the root.
    pub parent: usize,
    /// Camera whose pose is chained through `parent`.
    pub child: usize,
    /// Views both cameras saw.
    pub shared_views: usize,
}

/// Initial poses: camera poses (root frame → camera) and board poses (board → root frame).
#[derive(Debug, Clone)]
pub struct InitialPoses {
    /// Root frame → camera, per camera.
    pub cameras: Vec<Isometry3<f64>>,
    /// Board → root frame, per view (`None` where no camera saw the board).
    pub boards: Vec<Option<Isometry3<f64>>>,
    /// The tree the cameras were chained through.
    pub tree: Vec<TreeEdge>,
}

/// Chordal L2 mean of rotations: the rotation nearest the sum of the matrices.
fn mean_rotation(rs: &[UnitQuaternion<f64>]) -> UnitQuaternion<f64> {
    let sum: Matrix3<f64> = rs.iter().map(|q| *q.to_rotation_matrix().matrix()).sum();
    let rot = Rotation3::from_matrix_eps(&sum, 1e-12, 200, rs[0].to_rotation_matrix());
    UnitQuaternion::from_rotation_matrix(&rot)
}

/// Mean of rigid transforms: chordal mean rotation, arithmetic mean translation.
pub fn mean_pose(poses: &[Isometry3<f64>]) -> Option<Isometry3<f64>> {
    if poses.is_empty() {
        return None;
    }
    let r = mean_rotation(&poses.iter().map(|p| p.rotation).collect::<Vec<_>>());
    let t: Vector3<f64> = poses.iter().map(|p| p.translation.vector).sum::<Vector3<f64>>() / poses.len() as f64;
    Some(Isometry3::from_parts(Translation3::from(t), r))
}

/// Builds the initial poses from per-camera board poses `board_in_camera[c][v]` (board → camera c).
///
/// Returns `Err(camera)` naming a camera that shares no view with the cameras already placed.
pub fn initial_poses(board_in_camera: &[Vec<Option<Isometry3<f64>>>], root: usize) -> Result<InitialPoses, usize> {
    let n = board_in_camera.len();
    let views = board_in_camera.first().map_or(0, Vec::len);
    let shared = |a: usize, b: usize| {
        (0..views).filter(|&v| board_in_camera[a][v].is_some() && board_in_camera[b][v].is_some()).collect::<Vec<_>>()
    };
    let mut placed = vec![false; n];
    let mut poses = vec![Isometry3::identity(); n];
    let mut depth = vec![0usize; n];
    let mut tree = Vec::new();
    placed[root] = true;
    // Prim's algorithm for a maximum spanning tree; ties go to the lower camera index.
    for _ in 1..n {
        let mut best: Option<(usize, usize, Vec<usize>)> = None;
        for p in (0..n).filter(|&p| placed[p]) {
            for c in (0..n).filter(|&c| !placed[c]) {
                let s = shared(p, c);
                if !s.is_empty() && best.as_ref().is_none_or(|(_, _, b)| s.len() > b.len()) {
                    best = Some((p, c, s));
                }
            }
        }
        let Some((p, c, s)) = best else {
            return Err((0..n).find(|&c| !placed[c]).unwrap_or(root));
        };
        // child ← parent from each shared view: T_c←v · T_p←v⁻¹.
        let rel: Vec<_> =
            s.iter().filter_map(|&v| Some(board_in_camera[c][v]? * board_in_camera[p][v]?.inverse())).collect();
        let Some(rel) = mean_pose(&rel) else { return Err(c) };
        poses[c] = rel * poses[p];
        depth[c] = depth[p] + 1;
        placed[c] = true;
        tree.push(TreeEdge { parent: p, child: c, shared_views: s.len() });
    }
    // Board poses: from the camera closest to the root (fewest chained estimates) that saw it.
    let boards = (0..views)
        .map(|v| {
            (0..n)
                .filter_map(|c| board_in_camera[c][v].map(|b| (depth[c], c, b)))
                .min_by_key(|(d, c, _)| (*d, *c))
                .map(|(_, c, b)| poses[c].inverse() * b)
        })
        .collect();
    Ok(InitialPoses { cameras: poses, boards, tree })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(axis: [f64; 3], angle: f64, t: [f64; 3]) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_scaled_axis(Vector3::from(axis).normalize() * angle),
        )
    }

    #[test]
    fn chains_exact_poses_through_the_tree() {
        // Three cameras: 0 and 2 never see the same view, so 2 must be chained through 1.
        let cams = [
            Isometry3::identity(),
            pose([0.0, 1.0, 0.0], 0.5, [0.2, 0.0, 0.0]),
            pose([0.0, 1.0, 0.2], 1.1, [0.4, 0.1, 0.0]),
        ];
        let boards = [
            pose([1.0, 0.0, 0.0], 0.2, [0.0, 0.0, 1.0]),
            pose([1.0, 1.0, 0.0], 0.3, [0.1, 0.0, 1.2]),
            pose([0.0, 0.0, 1.0], 0.4, [0.0, 0.1, 0.9]),
        ];
        let seen = [[true, true, false], [true, true, true], [false, true, true]];
        let obs: Vec<Vec<_>> =
            (0..3).map(|c| (0..3).map(|v| seen[c][v].then(|| cams[c] * boards[v])).collect()).collect();
        // Camera 0 and 2 share view 1 only; 1 shares two views with each: the tree is 0-1-2.
        let init = initial_poses(&obs, 0).expect("connected");
        assert_eq!(init.tree[0], TreeEdge { parent: 0, child: 1, shared_views: 2 });
        assert_eq!(init.tree[1], TreeEdge { parent: 1, child: 2, shared_views: 2 });
        for c in 0..3 {
            assert!((init.cameras[c].to_homogeneous() - cams[c].to_homogeneous()).abs().max() < 1e-12);
        }
        for v in 0..3 {
            let b = init.boards[v].expect("seen");
            assert!((b.to_homogeneous() - boards[v].to_homogeneous()).abs().max() < 1e-12);
        }
    }

    #[test]
    fn disconnected_camera_is_named() {
        let b = Some(Isometry3::identity());
        let obs = vec![vec![b, None], vec![b, None], vec![None, b]];
        assert_eq!(initial_poses(&obs, 0).err(), Some(2));
    }
}
