//! Integration tests of hullcut-calib: agreement with OpenCV (projection, undistortion, rig.yaml,
//! stereo calibration of real photos) and a synthetic six-camera calibration against ground truth.

mod import;
mod opencv_agreement;
mod stereo_photos;
mod synthetic;
