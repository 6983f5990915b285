//! The crate's layering: the deformation model (src/model) never uses cutting and contact
//! (src/cut), which build on it.

use std::path::{Path, PathBuf};

fn sources(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).expect("a source folder") {
        let path = entry.expect("an entry").path();
        if path.is_dir() {
            out.extend(sources(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    out
}

#[test]
fn the_deformation_model_never_uses_cutting() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/src"));
    let cut: Vec<String> = sources(&root.join("cut"))
        .iter()
        .filter_map(|p| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .filter(|s| s != "mod")
        .collect();
    assert!(cut.len() >= 8, "{cut:?}");
    let model = sources(&root.join("model"));
    assert!(model.len() >= 12, "{model:?}");
    for path in model {
        let text = std::fs::read_to_string(&path).expect("readable");
        for line in text.lines().map(str::trim_start).filter(|l| !l.starts_with("//")) {
            for module in cut.iter().map(String::as_str).chain(["cut"]) {
                let uses =
                    [format!("crate::{module}::"), format!("crate::{module};"), format!("super::super::{module}")];
                assert!(
                    !uses.iter().any(|u| line.contains(u.as_str())),
                    "{} uses cutting ({module}): {line}",
                    path.display()
                );
            }
            for item in ["CutSim", "CutTopology", "Obstacle", "SweptSurface", "crate::Table"] {
                assert!(!line.contains(item), "{} uses cutting ({item}): {line}", path.display());
            }
        }
    }
}
