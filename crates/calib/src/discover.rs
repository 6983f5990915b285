//! Finding the calibration images: one folder per camera, simultaneous views share a file name.

use std::path::{Path, PathBuf};

use crate::CalibError;

/// Image file extensions read (case-insensitive).
const IMAGE_EXTENSIONS: [&str; 7] = ["png", "jpg", "jpeg", "bmp", "tif", "tiff", "pgm"];

/// The calibration images found under a folder.
#[derive(Debug, Clone)]
pub struct ImageSet {
    /// The folder that was searched.
    pub root: PathBuf,
    /// Camera names (sub-folder names) in natural order (cam2 before cam10).
    pub cameras: Vec<String>,
    /// Every file name that occurs in any camera folder, in natural order.
    pub views: Vec<String>,
    /// `paths[camera][view]`: the image, where that camera has one.
    pub paths: Vec<Vec<Option<PathBuf>>>,
}

pub use hullcut_rig::natural_cmp;

fn is_image(p: &Path) -> bool {
    p.extension().and_then(|e| e.to_str()).is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)))
}

fn list(dir: &Path) -> Result<Vec<PathBuf>, CalibError> {
    let entries = std::fs::read_dir(dir).map_err(|source| CalibError::Folder { path: dir.to_owned(), source })?;
    let mut out = Vec::new();
    for e in entries {
        let e = e.map_err(|source| CalibError::Folder { path: dir.to_owned(), source })?;
        out.push(e.path());
    }
    Ok(out)
}

/// Lists the camera folders under `root` and their images.
pub fn discover_images(root: &Path) -> Result<ImageSet, CalibError> {
    let mut cameras: Vec<(String, Vec<String>)> = Vec::new();
    for dir in list(root)?.into_iter().filter(|p| p.is_dir()) {
        let Some(name) = dir.file_name().and_then(|n| n.to_str()).map(str::to_owned) else { continue };
        let mut files: Vec<String> = list(&dir)?
            .into_iter()
            .filter(|p| p.is_file() && is_image(p))
            .filter_map(|p| p.file_name().and_then(|n| n.to_str()).map(str::to_owned))
            .collect();
        if files.is_empty() {
            continue;
        }
        files.sort_by(|a, b| natural_cmp(a, b));
        cameras.push((name, files));
    }
    if cameras.is_empty() {
        return Err(CalibError::NoCameras { path: root.to_owned() });
    }
    cameras.sort_by(|a, b| natural_cmp(&a.0, &b.0));
    let mut views: Vec<String> = cameras.iter().flat_map(|(_, f)| f.iter().cloned()).collect();
    views.sort_by(|a, b| natural_cmp(a, b));
    views.dedup();
    let paths = cameras
        .iter()
        .map(|(cam, files)| {
            views
                .iter()
                .map(|v| files.binary_search_by(|f| natural_cmp(f, v)).ok().map(|_| root.join(cam).join(v)))
                .collect()
        })
        .collect();
    Ok(ImageSet { root: root.to_owned(), cameras: cameras.into_iter().map(|(c, _)| c).collect(), views, paths })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order() {
        let mut v = vec!["cam10", "cam2", "cam1", "img010.png", "img9.png"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, ["cam1", "cam2", "cam10", "img9.png", "img010.png"]);
    }
}
