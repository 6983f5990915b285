//! Progress bars on long work (hidden when stderr is not a terminal).

use indicatif::{ProgressBar, ProgressStyle};

/// A counting progress bar with a message.
pub fn bar(len: u64, message: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    let style = ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} ({elapsed}, eta {eta})")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    pb.set_style(style);
    pb.set_message(message.to_owned());
    pb
}
