//! Reading a recording back: which entities an `.rrd` file holds, for tests and checks.

use std::collections::BTreeSet;
use std::path::Path;

use rerun::external::re_log_encoding::DecoderApp;
use rerun::log::{Chunk, LogMsg};

use crate::VizError;

/// Every entity path an `.rrd` file logs data to (e.g. `/world/tissue/surface`), read with
/// rerun's own decoder.
pub fn rrd_entities(path: &Path) -> Result<BTreeSet<String>, VizError> {
    let read = |message: String| VizError::Read { path: path.display().to_string(), message };
    let file = std::fs::File::open(path).map_err(|e| read(e.to_string()))?;
    let messages = DecoderApp::decode_eager(std::io::BufReader::new(file)).map_err(|e| read(e.to_string()))?;
    let mut entities = BTreeSet::new();
    for message in messages {
        if let LogMsg::ArrowMsg(_, arrow) = message.map_err(|e| read(e.to_string()))? {
            let chunk = Chunk::from_arrow_msg(&arrow).map_err(|e| read(e.to_string()))?;
            entities.insert(chunk.entity_path().to_string());
        }
    }
    Ok(entities)
}
