//! Helpers shared by the binary's test files.

use std::path::Path;

/// A CSV file read with the csv crate: its header and rows, every row as wide as the header.
pub fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let mut reader = csv::Reader::from_path(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let header: Vec<String> = reader.headers().expect("a header").iter().map(str::to_owned).collect();
    let rows: Vec<Vec<String>> = reader
        .records()
        .map(|r| r.unwrap_or_else(|e| panic!("{}: {e}", path.display())).iter().map(str::to_owned).collect())
        .collect();
    for (k, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), header.len(), "{} row {}: {row:?} under {header:?}", path.display(), k + 1);
    }
    (header, rows)
}
