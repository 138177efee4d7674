//! `results.parquet`: a sweep's typed columns ([`super::table`]) as a Parquet file, written
//! here in the subset of the format a flat table of nullable columns needs (no Parquet
//! library: the `parquet` crate without Arrow or codecs added about 30 s of CPU to a check
//! build and 75 s to a build, for some 200 lines).
//!
//! The layout (Apache Parquet format specification, `parquet.thrift`): the magic `PAR1`; per
//! column one chunk of one data page (v1, `PLAIN` values, definition levels in the
//! RLE/bit-packed hybrid with bit width 1, uncompressed); the `FileMetaData` in the Thrift
//! compact protocol, its length (4 bytes, little-endian) and `PAR1` again. One row group; every
//! column `OPTIONAL` (nulls): `Int64` as INT64, `Float64` as DOUBLE, `Boolean` as BOOLEAN, text
//! as BYTE_ARRAY with the String logical type (UTF8). polars, pandas (pyarrow) and DuckDB read
//! it.

use super::table::Column;

/// Thrift compact protocol types.
const T_I32: u8 = 5;
const T_I64: u8 = 6;
const T_BINARY: u8 = 8;
const T_LIST: u8 = 9;
const T_STRUCT: u8 = 12;

/// A Thrift compact-protocol writer (only what the metadata needs).
struct Thrift {
    buf: Vec<u8>,
    /// The last field id of each open struct.
    last: Vec<i16>,
}

impl Thrift {
    fn new() -> Self {
        Self {
            buf: Vec::new(),
            last: vec![0],
        }
    }

    fn varint(&mut self, mut v: u64) {
        while v >= 0x80 {
            self.buf.push((v as u8) | 0x80);
            v >>= 7;
        }
        self.buf.push(v as u8);
    }

    fn zigzag(&mut self, v: i64) {
        self.varint(((v << 1) ^ (v >> 63)) as u64);
    }

    fn field(&mut self, id: i16, kind: u8) {
        let last = self.last.last().copied().unwrap_or(0);
        let delta = id - last;
        if (1..=15).contains(&delta) {
            self.buf.push(((delta as u8) << 4) | kind);
        } else {
            self.buf.push(kind);
            self.zigzag(i64::from(id));
        }
        if let Some(l) = self.last.last_mut() {
            *l = id;
        }
    }

    fn i32(&mut self, id: i16, v: i32) {
        self.field(id, T_I32);
        self.zigzag(i64::from(v));
    }

    fn i64(&mut self, id: i16, v: i64) {
        self.field(id, T_I64);
        self.zigzag(v);
    }

    fn string(&mut self, id: i16, s: &str) {
        self.field(id, T_BINARY);
        self.bytes(s.as_bytes());
    }

    fn bytes(&mut self, b: &[u8]) {
        self.varint(b.len() as u64);
        self.buf.extend_from_slice(b);
    }

    /// Opens a struct as field `id`.
    fn begin(&mut self, id: i16) {
        self.field(id, T_STRUCT);
        self.last.push(0);
    }

    /// Opens a struct that is an element of a list.
    fn begin_element(&mut self) {
        self.last.push(0);
    }

    /// Closes the innermost struct.
    fn end(&mut self) {
        self.buf.push(0);
        self.last.pop();
    }

    /// A list header as field `id`: `n` elements of type `kind`.
    fn list(&mut self, id: i16, kind: u8, n: usize) {
        self.field(id, T_LIST);
        if n < 15 {
            self.buf.push(((n as u8) << 4) | kind);
        } else {
            self.buf.push(0xF0 | kind);
            self.varint(n as u64);
        }
    }
}

/// Parquet's physical types, encodings and other enum values used here.
const INT64: i32 = 2;
const DOUBLE: i32 = 5;
const BOOLEAN: i32 = 0;
const BYTE_ARRAY: i32 = 6;
const OPTIONAL: i32 = 1;
const UTF8: i32 = 0;
const PLAIN: i32 = 0;
const RLE: i32 = 3;
const DATA_PAGE: i32 = 0;
const UNCOMPRESSED: i32 = 0;

/// The definition levels (1 present, 0 null) as 4-byte length + RLE runs (bit width 1).
fn levels(present: &[bool]) -> Vec<u8> {
    let mut runs = Thrift::new();
    let mut k = 0;
    while k < present.len() {
        let v = present[k];
        let len = present[k..].iter().take_while(|&&p| p == v).count();
        runs.varint((len as u64) << 1);
        runs.buf.push(u8::from(v));
        k += len;
    }
    let mut out = (runs.buf.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(&runs.buf);
    out
}

/// A column's physical type, whether it is text, its presence mask and `PLAIN` values.
fn encode(col: &Column) -> (i32, bool, Vec<bool>, Vec<u8>) {
    let mut plain = Vec::new();
    match col {
        Column::Int(v) => {
            for x in v.iter().flatten() {
                plain.extend_from_slice(&x.to_le_bytes());
            }
            (INT64, false, v.iter().map(Option::is_some).collect(), plain)
        }
        Column::Float(v) => {
            for x in v.iter().flatten() {
                plain.extend_from_slice(&x.to_le_bytes());
            }
            (
                DOUBLE,
                false,
                v.iter().map(Option::is_some).collect(),
                plain,
            )
        }
        Column::Bool(v) => {
            let bits: Vec<bool> = v.iter().flatten().copied().collect();
            plain = vec![0u8; bits.len().div_ceil(8)];
            for (k, b) in bits.iter().enumerate() {
                plain[k / 8] |= u8::from(*b) << (k % 8);
            }
            (
                BOOLEAN,
                false,
                v.iter().map(Option::is_some).collect(),
                plain,
            )
        }
        Column::Text(v) => {
            for s in v.iter().flatten() {
                plain.extend_from_slice(&(s.len() as u32).to_le_bytes());
                plain.extend_from_slice(s.as_bytes());
            }
            (
                BYTE_ARRAY,
                true,
                v.iter().map(Option::is_some).collect(),
                plain,
            )
        }
    }
}

/// The file's bytes.
pub fn to_bytes(columns: &[(String, Column)]) -> Result<Vec<u8>, String> {
    let rows = columns.first().map_or(0, |(_, c)| match c {
        Column::Int(v) => v.len(),
        Column::Float(v) => v.len(),
        Column::Bool(v) => v.len(),
        Column::Text(v) => v.len(),
    });
    let too_big = || "the table is too large for one Parquet page per column".to_string();
    let rows_i32 = i32::try_from(rows).map_err(|_| too_big())?;
    let mut file = b"PAR1".to_vec();
    // (name, type, is text, page offset, chunk size)
    let mut chunks = Vec::with_capacity(columns.len());
    for (name, col) in columns {
        let (kind, text, present, plain) = encode(col);
        if present.len() != rows {
            return Err(format!("column {name}: {} rows, not {rows}", present.len()));
        }
        let mut page = levels(&present);
        page.extend_from_slice(&plain);
        let size = i32::try_from(page.len()).map_err(|_| too_big())?;
        let mut h = Thrift::new();
        h.i32(1, DATA_PAGE);
        h.i32(2, size);
        h.i32(3, size);
        h.begin(5);
        h.i32(1, rows_i32);
        h.i32(2, PLAIN);
        h.i32(3, RLE);
        h.i32(4, RLE);
        h.end();
        h.buf.push(0);
        let offset = file.len() as i64;
        file.extend_from_slice(&h.buf);
        file.extend_from_slice(&page);
        chunks.push((name, kind, text, offset, (h.buf.len() + page.len()) as i64));
    }
    let mut m = Thrift::new();
    m.i32(1, 1);
    m.list(2, T_STRUCT, columns.len() + 1);
    m.begin_element();
    m.string(4, "schema");
    m.i32(5, i32::try_from(columns.len()).map_err(|_| too_big())?);
    m.end();
    for (name, kind, text, _, _) in &chunks {
        m.begin_element();
        m.i32(1, *kind);
        m.i32(3, OPTIONAL);
        m.string(4, name);
        if *text {
            m.i32(6, UTF8);
            m.begin(10); // LogicalType, a union: STRING (1), an empty struct
            m.begin(1);
            m.end();
            m.end();
        }
        m.end();
    }
    m.i64(3, rows as i64);
    m.list(4, T_STRUCT, 1);
    m.begin_element();
    m.list(1, T_STRUCT, chunks.len());
    let mut total = 0;
    for (name, kind, _, offset, size) in &chunks {
        total += size;
        m.begin_element();
        m.i64(2, *offset);
        m.begin(3);
        m.i32(1, *kind);
        m.list(2, T_I32, 2);
        m.zigzag(i64::from(PLAIN));
        m.zigzag(i64::from(RLE));
        m.list(3, T_BINARY, 1);
        m.bytes(name.as_bytes());
        m.i32(4, UNCOMPRESSED);
        m.i64(5, rows as i64);
        m.i64(6, *size);
        m.i64(7, *size);
        m.i64(9, *offset);
        m.end();
        m.end();
    }
    m.i64(2, total);
    m.i64(3, rows as i64);
    m.end();
    m.string(6, concat!("pmsm-sim ", env!("CARGO_PKG_VERSION")));
    m.buf.push(0);
    let footer = u32::try_from(m.buf.len()).map_err(|_| too_big())?;
    file.extend_from_slice(&m.buf);
    file.extend_from_slice(&footer.to_le_bytes());
    file.extend_from_slice(b"PAR1");
    Ok(file)
}

/// Writes the columns to `path`; errors as text naming the file.
pub fn write(path: &std::path::Path, columns: &[(String, Column)]) -> Result<(), String> {
    let bytes = to_bytes(columns).map_err(|e| format!("{}: {e}", path.display()))?;
    std::fs::write(path, bytes).map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compact_protocol_known_answers() {
        let mut t = Thrift::new();
        t.i32(1, 1); // field 1, i32: 0x15, zigzag(1) = 2
        t.i64(3, -1); // delta 2, i64: 0x26, zigzag(-1) = 1
        t.i32(20, 300); // delta 17: long form 0x05, zigzag(20) = 40, zigzag(300) = 600 = ac 04
        t.list(21, T_STRUCT, 20); // delta 1, list: 0x19; 0xfc, 20
        assert_eq!(
            t.buf,
            [0x15, 2, 0x26, 1, 0x05, 40, 0xd8, 0x04, 0x19, 0xfc, 20]
        );
    }

    #[test]
    fn levels_are_rle_runs() {
        // 3 present, 1 null, 2 present: runs (3,1) (1,0) (2,1); 6 bytes after the length.
        let l = levels(&[true, true, true, false, true, true]);
        assert_eq!(l, [6, 0, 0, 0, 6, 1, 2, 0, 4, 1]);
    }

    #[test]
    fn framing() {
        let cols = vec![
            ("a".to_string(), Column::Int(vec![Some(1), None])),
            ("b".to_string(), Column::Text(vec![None, Some("x".into())])),
        ];
        let b = to_bytes(&cols).unwrap();
        assert_eq!(&b[..4], b"PAR1");
        assert_eq!(&b[b.len() - 4..], b"PAR1");
        let n = u32::from_le_bytes(b[b.len() - 8..b.len() - 4].try_into().unwrap()) as usize;
        assert!(n > 0 && n < b.len() - 12);
        let bad = vec![
            ("a".to_string(), Column::Int(vec![Some(1)])),
            ("b".to_string(), Column::Bool(vec![])),
        ];
        assert!(to_bytes(&bad).unwrap_err().contains("column b"));
    }
}
