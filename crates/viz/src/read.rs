//! Reading a recording back: which entities an `.rrd` file holds, for tests and checks.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use rerun::external::re_log_encoding::DecoderApp;
use rerun::log::{Chunk, LogMsg};

use crate::VizError;

/// Every entity path an `.rrd` file logs data to (e.g. `/world/tissue/surface`), read with
/// rerun's own decoder; an error for a file that is not a recording (or holds no message).
pub fn rrd_entities(path: &Path) -> Result<BTreeSet<String>, VizError> {
    let mut entities = BTreeSet::new();
    for_each_chunk(path, |chunk| {
        entities.insert(chunk.entity_path().to_string());
    })?;
    Ok(entities)
}

/// Per entity path of an `.rrd` file, how many rows it logged on the timelines (static data, such
/// as a series' style, not counted; an entity with static data only maps to 0).
pub fn rrd_timeline_rows(path: &Path) -> Result<BTreeMap<String, usize>, VizError> {
    let mut rows = BTreeMap::new();
    for_each_chunk(path, |chunk| {
        let n = if chunk.is_static() { 0 } else { chunk.num_rows() };
        *rows.entry(chunk.entity_path().to_string()).or_insert(0) += n;
    })?;
    Ok(rows)
}

/// Calls `f` with every chunk of an `.rrd` file, decoded by rerun's own decoder.
fn for_each_chunk(path: &Path, mut f: impl FnMut(&Chunk)) -> Result<(), VizError> {
    let read = |message: String| VizError::Read { path: path.display().to_string(), message };
    let file = std::fs::File::open(path).map_err(|e| read(e.to_string()))?;
    let messages = DecoderApp::decode_eager(std::io::BufReader::new(file)).map_err(|e| read(e.to_string()))?;
    let mut any = false;
    for message in messages {
        any = true;
        if let LogMsg::ArrowMsg(_, arrow) = message.map_err(|e| read(e.to_string()))? {
            f(&Chunk::from_arrow_msg(&arrow).map_err(|e| read(e.to_string()))?);
        }
    }
    // A recording holds its store's description at least: nothing at all is not one.
    if any { Ok(()) } else { Err(read("no rerun message in it (empty, or not a recording)".to_owned())) }
}
