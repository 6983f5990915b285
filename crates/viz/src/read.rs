//! Reading a recording back: which entities an `.rrd` file holds, for tests and checks.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{Read as _, Seek as _, SeekFrom};
use std::path::Path;

use rerun::external::re_log_encoding::{DecoderApp, MessageHeader, RRD_FOURCC, StreamFooter, StreamHeader};
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
    let mut file = std::fs::File::open(path).map_err(|e| read(e.to_string()))?;
    let whole = whole_frames(&mut file).map_err(|e| read(e.to_string()))?;
    file.seek(SeekFrom::Start(0)).map_err(|e| read(e.to_string()))?;
    let messages =
        DecoderApp::decode_eager(std::io::BufReader::new(file.take(whole))).map_err(|e| read(e.to_string()))?;
    // Arrow asserts on some damaged buffers instead of returning an error (a slice offset of
    // 6 GB into a 576-byte buffer, found by `damaged_recordings_never_panic_the_readers`): such
    // a panic is the file's fault and is reported as its error.
    let decoded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut any = false;
        for message in messages {
            any = true;
            if let LogMsg::ArrowMsg(_, arrow) = message.map_err(|e| read(e.to_string()))? {
                f(&Chunk::from_arrow_msg(&arrow).map_err(|e| read(e.to_string()))?);
            }
        }
        Ok(any)
    }));
    let any = match decoded {
        Ok(any) => any?,
        Err(panic) => {
            let why = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("no message");
            return Err(read(format!("damaged: the decoder gave up on it ({why})")));
        }
    };
    // A recording holds its store's description at least: nothing at all is not one.
    if any { Ok(()) } else { Err(read("no rerun message in it (empty, or not a recording)".to_owned())) }
}

/// How many leading bytes of an `.rrd` file hold whole frames: the file up to the first message
/// whose stated length runs past its end (a recording cut short, or a damaged length that
/// rerun's decoder would try to allocate whole, up to exabytes), else the whole file. Walks the
/// framing by its headers (a stream header, then messages of a 16-byte header and their payload,
/// an end message followed by the stream's footer), reading nothing else; whatever it does not
/// recognize is left to the decoder.
fn whole_frames(file: &mut std::fs::File) -> std::io::Result<u64> {
    /// rerun 0.36's message kinds are 0 (the end of a stream) to 3; any other is no message.
    const LAST_MESSAGE_KIND: u64 = 3;
    let size = file.metadata()?.len();
    let (stream, header, footer) = (
        StreamHeader::ENCODED_SIZE_BYTES as u64,
        MessageHeader::ENCODED_SIZE_BYTES as u64,
        StreamFooter::ENCODED_SIZE_BYTES as u64,
    );
    let mut at = 0u64;
    loop {
        // A stream's header.
        let mut fourcc = [0u8; 4];
        if size - at < stream {
            return Ok(size);
        }
        file.seek(SeekFrom::Start(at))?;
        file.read_exact(&mut fourcc)?;
        if fourcc != RRD_FOURCC {
            return Ok(size);
        }
        at += stream;
        // Its messages.
        loop {
            if size - at < header {
                return Ok(size);
            }
            // Its kind and its payload's length, little-endian u64 each.
            let mut bytes = [0u8; MessageHeader::ENCODED_SIZE_BYTES];
            file.seek(SeekFrom::Start(at))?;
            file.read_exact(&mut bytes)?;
            let (kind, len) = (
                u64::from_le_bytes(bytes[..8].try_into().unwrap_or_default()),
                u64::from_le_bytes(bytes[8..16].try_into().unwrap_or_default()),
            );
            if kind > LAST_MESSAGE_KIND {
                // Not a message: the decoder looks for another stream here.
                break;
            }
            if len > size - at - header {
                return Ok(at);
            }
            at += header + len;
            if kind == 0 {
                // The end of a stream: its footer, then maybe another stream.
                if size - at < footer {
                    return Ok(size);
                }
                at += footer;
                break;
            }
        }
    }
}
