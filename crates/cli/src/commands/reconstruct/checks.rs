//! Input checks of `hullcut reconstruct` and `hullcut run` (frame sets read past a bad camera
//! image, reports checked for numbers that are not finite) and the per-camera disagreement
//! reconstruct reports.

use anyhow::bail;
use hullcut_dataset::Dataset;
use hullcut_hull::CarveStats;
pub(crate) use hullcut_pipeline::read::{Faults, read_frame_set};
use serde::{Deserialize, Serialize};

/// `--voxel` lies in (0, the workspace's side].
pub(crate) fn voxel(voxel: f64, extent: f64) -> anyhow::Result<()> {
    if !(voxel > 0.0 && voxel <= extent) {
        bail!(
            "--voxel {voxel}: the leaf size must be above 0 and at most the side of the carved workspace ({extent} m)"
        );
    }
    Ok(())
}

/// Whether masks come from the dataset's files (else segmented): `--masks auto|files|segment`.
pub(crate) fn masks_from_files(ds: &Dataset, masks: MaskSource) -> anyhow::Result<bool> {
    Ok(match masks {
        MaskSource::Files if !ds.has_masks() => bail!("--masks files: {} has no masks/", ds.root().display()),
        MaskSource::Files => true,
        MaskSource::Segment => false,
        MaskSource::Auto => ds.has_masks(),
    })
}

/// Where a command's masks come from (`--masks`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub(crate) enum MaskSource {
    /// The mask files under masks/ when the dataset has them, else segmented from the images.
    #[default]
    Auto,
    /// The mask files under masks/ (an error when there are none).
    Files,
    /// Segmented from the images (the mask files, if any, are the truth to compare with).
    Segment,
}

/// Paths of the numbers in a report that are not finite (`tissue.kinetic_energy_j`,
/// `memory[3].rss_mib`): serde_json writes them as null, which reads as "not measured". A
/// report is checked with this before it is written, so that a NaN is said, not hidden.
pub(crate) fn non_finite_fields(value: &impl Serialize) -> Vec<String> {
    let mut finder = NonFinite::default();
    // The finder's own methods never fail; a value whose Serialize fails is named as such.
    if value.serialize(&mut finder).is_err() {
        finder.found.push("(the report could not be walked)".to_owned());
    }
    finder.found
}

/// One step of a path into a report.
#[derive(Debug)]
enum Step {
    Key(String),
    Index(usize),
}

/// A serializer that writes nothing and notes where a float is not finite.
#[derive(Debug, Default)]
struct NonFinite {
    path: Vec<Step>,
    /// The key of the map entry whose value comes next.
    key: Option<String>,
    found: Vec<String>,
}

impl NonFinite {
    fn float(&mut self, v: f64) -> Result<(), std::fmt::Error> {
        if !v.is_finite() {
            let mut path = String::new();
            for step in &self.path {
                match step {
                    Step::Key(k) if path.is_empty() => path.push_str(k),
                    Step::Key(k) => {
                        path.push('.');
                        path.push_str(k);
                    }
                    Step::Index(i) => path.push_str(&format!("[{i}]")),
                }
            }
            self.found.push(if path.is_empty() { "(the value)".to_owned() } else { path });
        }
        Ok(())
    }

    fn under<T: ?Sized + Serialize>(&mut self, step: Step, value: &T) -> Result<(), std::fmt::Error> {
        self.path.push(step);
        let result = value.serialize(&mut *self);
        self.path.pop();
        result
    }

    /// Moves the innermost sequence index on by one.
    fn next_index(&mut self) {
        if let Some(Step::Index(i)) = self.path.last_mut() {
            *i += 1;
        }
    }
}

impl serde::Serializer for &mut NonFinite {
    type Ok = ();
    type Error = std::fmt::Error;
    type SerializeSeq = Self;
    type SerializeTuple = Self;
    type SerializeTupleStruct = Self;
    type SerializeTupleVariant = Self;
    type SerializeMap = Self;
    type SerializeStruct = Self;
    type SerializeStructVariant = Self;

    fn serialize_bool(self, _: bool) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_i8(self, _: i8) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_i16(self, _: i16) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_i32(self, _: i32) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_i64(self, _: i64) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_i128(self, _: i128) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_u8(self, _: u8) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_u16(self, _: u16) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_u32(self, _: u32) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_u64(self, _: u64) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_u128(self, _: u128) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_f32(self, v: f32) -> Result<(), Self::Error> {
        self.float(f64::from(v))
    }
    fn serialize_f64(self, v: f64) -> Result<(), Self::Error> {
        self.float(v)
    }
    fn serialize_char(self, _: char) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_str(self, _: &str) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_bytes(self, _: &[u8]) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_none(self) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_some<T>(self, value: &T) -> Result<(), Self::Error>
    where
        T: ?Sized + Serialize,
    {
        value.serialize(self)
    }
    fn serialize_unit(self) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_unit_variant(self, _: &'static str, _: u32, _: &'static str) -> Result<(), Self::Error> {
        Ok(())
    }
    fn serialize_newtype_struct<T>(self, _: &'static str, value: &T) -> Result<(), Self::Error>
    where
        T: ?Sized + Serialize,
    {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        value: &T,
    ) -> Result<(), Self::Error>
    where
        T: ?Sized + Serialize,
    {
        self.under(Step::Key(variant.to_owned()), value)
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Self, Self::Error> {
        self.path.push(Step::Index(0));
        Ok(self)
    }
    fn serialize_tuple(self, _: usize) -> Result<Self, Self::Error> {
        self.path.push(Step::Index(0));
        Ok(self)
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Self, Self::Error> {
        self.path.push(Step::Index(0));
        Ok(self)
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Self, Self::Error> {
        self.path.push(Step::Key(variant.to_owned()));
        self.path.push(Step::Index(0));
        Ok(self)
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Self, Self::Error> {
        Ok(self)
    }
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Self, Self::Error> {
        Ok(self)
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Self, Self::Error> {
        self.path.push(Step::Key(variant.to_owned()));
        Ok(self)
    }
}

/// The walker's sequence-like parts: each element is visited under its index; `end` leaves the
/// index (and, for a tuple variant, the variant's key) pushed when the part began.
macro_rules! indexed_part {
    ($trait:ident, $method:ident, $pops:literal) => {
        impl serde::ser::$trait for &mut NonFinite {
            type Ok = ();
            type Error = std::fmt::Error;
            fn $method<T>(&mut self, value: &T) -> Result<(), Self::Error>
            where
                T: ?Sized + Serialize,
            {
                value.serialize(&mut **self)?;
                self.next_index();
                Ok(())
            }
            fn end(self) -> Result<(), Self::Error> {
                for _ in 0..$pops {
                    self.path.pop();
                }
                Ok(())
            }
        }
    };
}

indexed_part!(SerializeSeq, serialize_element, 1);
indexed_part!(SerializeTuple, serialize_element, 1);
indexed_part!(SerializeTupleStruct, serialize_field, 1);
indexed_part!(SerializeTupleVariant, serialize_field, 2);

impl serde::ser::SerializeMap for &mut NonFinite {
    type Ok = ();
    type Error = std::fmt::Error;
    fn serialize_key<T>(&mut self, key: &T) -> Result<(), Self::Error>
    where
        T: ?Sized + Serialize,
    {
        // A key as its JSON text, without the quotes of a string.
        let text = serde_json::to_string(key).unwrap_or_else(|_| "?".to_owned());
        self.key = Some(text.trim_matches('"').to_owned());
        Ok(())
    }
    fn serialize_value<T>(&mut self, value: &T) -> Result<(), Self::Error>
    where
        T: ?Sized + Serialize,
    {
        let key = self.key.take().unwrap_or_else(|| "?".to_owned());
        self.under(Step::Key(key), value)
    }
    fn end(self) -> Result<(), Self::Error> {
        Ok(())
    }
}

impl serde::ser::SerializeStruct for &mut NonFinite {
    type Ok = ();
    type Error = std::fmt::Error;
    fn serialize_field<T>(&mut self, key: &'static str, value: &T) -> Result<(), Self::Error>
    where
        T: ?Sized + Serialize,
    {
        self.under(Step::Key(key.to_owned()), value)
    }
    fn end(self) -> Result<(), Self::Error> {
        Ok(())
    }
}

impl serde::ser::SerializeStructVariant for &mut NonFinite {
    type Ok = ();
    type Error = std::fmt::Error;
    fn serialize_field<T>(&mut self, key: &'static str, value: &T) -> Result<(), Self::Error>
    where
        T: ?Sized + Serialize,
    {
        self.under(Step::Key(key.to_owned()), value)
    }
    fn end(self) -> Result<(), Self::Error> {
        self.path.pop();
        Ok(())
    }
}

/// Lone refutations of one camera, summed over frames.
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct LoneRefutations {
    camera: String,
    cells: u64,
}

/// Which view disagreed with all the others, and how often (docs/reports.md).
#[derive(Debug, Serialize, Deserialize)]
pub(super) struct ViewDisagreement {
    lone_refutations: Vec<LoneRefutations>,
    disagreed_most: Option<String>,
    most_over_median: Option<f64>,
}

impl ViewDisagreement {
    /// Zero counts for the rig's cameras.
    pub(super) fn new(cameras: &[String]) -> Self {
        ViewDisagreement {
            lone_refutations: cameras.iter().map(|c| LoneRefutations { camera: c.clone(), cells: 0 }).collect(),
            disagreed_most: None,
            most_over_median: None,
        }
    }

    /// Adds one carving's counts (rig order).
    pub(super) fn add(&mut self, stats: &CarveStats) {
        for (l, n) in self.lone_refutations.iter_mut().zip(&stats.lone_refutations) {
            l.cells += n;
        }
    }

    /// Names the camera with the most lone refutations (the first of equals; none when no camera
    /// refuted a cell alone) and its count over the median camera's.
    pub(super) fn finish(&mut self) {
        let mut counts: Vec<u64> = self.lone_refutations.iter().map(|l| l.cells).collect();
        counts.sort_unstable();
        let median = match counts.len() {
            0 => 0.0,
            n if n % 2 == 1 => counts[n / 2] as f64,
            n => (counts[n / 2 - 1] + counts[n / 2]) as f64 / 2.0,
        };
        let most = self
            .lone_refutations
            .iter()
            .enumerate()
            .max_by_key(|&(k, l)| (l.cells, std::cmp::Reverse(k)))
            .map(|(_, l)| l)
            .filter(|l| l.cells > 0);
        self.disagreed_most = most.map(|l| l.camera.clone());
        self.most_over_median = most.filter(|_| median > 0.0).map(|l| l.cells as f64 / median);
    }

    /// One line for the terminal, when a camera disagreed at all.
    pub(super) fn summary(&self) -> Option<String> {
        let name = self.disagreed_most.as_ref()?;
        let n = self.lone_refutations.iter().find(|l| &l.camera == name).map_or(0, |l| l.cells);
        let ratio = self
            .most_over_median
            .map_or(String::from("the median camera has none"), |r| format!("{r:.1}x the median camera"));
        Some(format!(
            "  views: {name} disagreed most ({n} cells it alone refuted, {ratio}; a view with a bad mask or \
             calibration stands out at several times)"
        ))
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    #[derive(Serialize, Deserialize)]
    struct Inner {
        fine: f64,
        energy: f64,
    }

    #[derive(Serialize, Deserialize)]
    enum Kind {
        Pair(f64, f32),
    }

    #[derive(Serialize, Deserialize)]
    struct Report {
        name: &'static str,
        fps: f64,
        mean: Option<f64>,
        inner: Inner,
        samples: Vec<[f64; 2]>,
        by_label: BTreeMap<String, f64>,
        kind: Kind,
    }

    #[test]
    fn every_number_that_is_not_finite_is_named_by_its_path() {
        let report = Report {
            name: "run",
            fps: 12.0,
            mean: Some(f64::NAN),
            inner: Inner { fine: 1.0, energy: f64::INFINITY },
            samples: vec![[1.0, 2.0], [3.0, f64::NEG_INFINITY]],
            by_label: BTreeMap::from([("hand".to_owned(), 0.5), ("scalpel".to_owned(), f64::NAN)]),
            kind: Kind::Pair(f64::NAN, 1.0),
        };
        assert_eq!(
            non_finite_fields(&report),
            ["mean", "inner.energy", "samples[1][1]", "by_label.scalpel", "kind.Pair[0]"]
        );
        // serde_json would write them all as null, the same as "not measured".
        let json = serde_json::to_value(&report).expect("JSON");
        assert!(json["mean"].is_null() && json["inner"]["energy"].is_null());
        let clean = Inner { fine: 1.0, energy: 2.0 };
        assert!(non_finite_fields(&clean).is_empty());
    }
}
