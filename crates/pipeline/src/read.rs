//! Frame sets read past a bad camera image: a view that cannot be used (an unreadable or
//! truncated PNG, a camera whose files stop mid-recording, a mask with labels carving does not
//! know) is left out of its frame set, counted and listed ([`Faults`]); the frame set goes on with
//! the other cameras.

use hullcut_dataset::{Dataset, FrameSet, View, label};
use serde::{Deserialize, Serialize};

use crate::error::{Context as _, Error, fail};

/// A view's mask holds only the labels carving knows (0, 1, 2, 255); anything else (a mask saved
/// with other values, a palette PNG's indices) is an error naming the file, the camera and the
/// frame.
pub fn view_labels(ds: &Dataset, frame: u64, view: &View) -> Result<(), Error> {
    let bad = |v: &u8| ![label::BACKGROUND, label::HAND, label::SCALPEL, label::UNKNOWN].contains(v);
    let Some(mask) = &view.mask else { return Ok(()) };
    let raw = mask.as_raw();
    let Some(first) = raw.iter().position(bad) else { return Ok(()) };
    let w = (mask.width() as usize).max(1);
    fail!(
        "{}: label mask of camera `{}`, frame {}: pixel ({}, {}) holds {} ({} pixels outside the labels \
         0 background, 1 hand, 2 scalpel, 255 unknown)",
        ds.mask_path(frame, view.camera).context("the mask's path")?.display(),
        camera_name(ds, view.camera),
        frame,
        first % w,
        first / w,
        raw[first],
        raw.iter().filter(|v| bad(v)).count()
    );
}

/// The rig's name of camera `camera` (its index where the rig has no such camera).
pub fn camera_name(ds: &Dataset, camera: usize) -> String {
    ds.rig().cameras.get(camera).map_or_else(|| format!("camera {camera}"), |c| c.name.clone())
}

/// A camera image (or a whole frame set) that could not be used: unreadable (a corrupt or
/// truncated PNG, a camera whose files stop mid-recording), or a mask with labels carving does
/// not know.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ViewFault {
    /// The frame.
    pub frame: u64,
    /// The camera; null when the frame set as a whole could not be read.
    pub camera: Option<String>,
    /// Why, naming the file.
    pub reason: String,
}

impl std::fmt::Display for ViewFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.camera {
            Some(camera) => write!(f, "frame {}, camera {camera}: {}", self.frame, self.reason),
            None => write!(f, "frame {}: {}", self.frame, self.reason),
        }
    }
}

/// Faults listed in a report at most (the count goes on past them).
pub const MAX_LISTED_FAULTS: usize = 100;

/// The faults of a run: every one counted, the first [`MAX_LISTED_FAULTS`] listed.
#[derive(Debug, Default, Serialize, Deserialize)]
pub struct Faults {
    /// Camera images left out (unreadable, or with unknown labels).
    pub views: u64,
    /// Frame sets left out whole (no camera's image could be used).
    pub frame_sets: u64,
    /// The first faults, in order.
    pub listed: Vec<ViewFault>,
}

impl Faults {
    /// Counts and lists one read's faults; `used` tells whether the frame set went on.
    pub fn add(&mut self, faults: Vec<ViewFault>, used: bool) {
        if !used && !faults.is_empty() {
            self.frame_sets += 1;
        }
        for fault in faults {
            self.views += u64::from(fault.camera.is_some());
            if self.listed.len() < MAX_LISTED_FAULTS {
                self.listed.push(fault);
            }
        }
    }

    /// Whether anything was left out.
    pub fn any(&self) -> bool {
        self.views > 0 || self.frame_sets > 0
    }

    /// One sentence for the terminal and the exit error, with the first fault.
    pub fn summary(&self) -> String {
        let first = self.listed.first().map_or_else(String::new, |f| format!(" (the first: {f})"));
        format!(
            "{} camera image(s) and {} whole frame set(s) could not be used and were left out{first}; the report lists them",
            self.views, self.frame_sets
        )
    }
}

/// Reads frame set `frame` (masks when `with_masks`), going on without a camera whose image or
/// mask cannot be read or holds labels carving does not know: that view is missing from the
/// frame set and each such camera is a fault. `None` when no camera's image could be used, or
/// the frame set could not be read at all (its faults say why).
pub fn read_frame_set(ds: &Dataset, frame: u64, with_masks: bool) -> (Option<FrameSet>, Vec<ViewFault>) {
    let fault =
        |camera: Option<usize>, reason: String| ViewFault { frame, camera: camera.map(|c| camera_name(ds, c)), reason };
    let mut faults = Vec::new();
    let views = match ds.read_frame_set(frame, with_masks) {
        Ok(set) => set.views,
        Err(whole) => {
            // View by view, keeping the cameras that read.
            let mut views = Vec::with_capacity(ds.rig().len());
            for camera in 0..ds.rig().len() {
                let Some(timestamp_ns) = ds.timestamp(frame, camera) else {
                    views.push(None);
                    continue;
                };
                let read = ds.read_image(frame, camera).and_then(|image| {
                    let mask = if with_masks { Some(ds.read_mask(frame, camera)?) } else { None };
                    Ok(View { camera, timestamp_ns, image, mask })
                });
                match read {
                    Ok(view) => views.push(Some(view)),
                    Err(e) => {
                        faults.push(fault(Some(camera), e.to_string()));
                        views.push(None);
                    }
                }
            }
            if faults.is_empty() {
                // Not a camera's fault (the frame set itself): nothing of it is used.
                return (None, vec![fault(None, whole.to_string())]);
            }
            views
        }
    };
    let views: Vec<Option<View>> = views
        .into_iter()
        .map(|v| {
            let view = v?;
            match view_labels(ds, frame, &view) {
                Ok(()) => Some(view),
                Err(e) => {
                    faults.push(fault(Some(view.camera), e.to_string()));
                    None
                }
            }
        })
        .collect();
    if views.iter().all(Option::is_none) && !faults.is_empty() {
        return (None, faults);
    }
    let timestamp_ns = FrameSet::median_timestamp(&views);
    (Some(FrameSet { frame, timestamp_ns, views }), faults)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_are_counted_past_the_listed_ones_and_summed_up_with_the_first() {
        let mut faults = Faults::default();
        let fault = |frame: u64, camera: Option<&str>| ViewFault {
            frame,
            camera: camera.map(str::to_owned),
            reason: format!("cam/{frame:06}.png: truncated"),
        };
        faults.add(vec![fault(4, Some("cam2"))], true);
        faults.add(vec![fault(6, None)], false);
        for frame in 0..(MAX_LISTED_FAULTS as u64 + 10) {
            faults.add(vec![fault(frame, Some("cam0"))], true);
        }
        assert_eq!((faults.views, faults.frame_sets), (MAX_LISTED_FAULTS as u64 + 11, 1));
        assert_eq!(faults.listed.len(), MAX_LISTED_FAULTS);
        let summary = faults.summary();
        assert!(summary.contains("frame 4, camera cam2: cam/000004.png: truncated"), "{summary}");
        assert!(Faults::default().summary().contains("0 camera image(s)") && !Faults::default().any());
    }
}
