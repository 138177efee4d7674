//! `results.parquet`: a sweep's typed columns ([`super::table`]) as one Parquet row group,
//! every column optional (nulls), uncompressed: `Int64` as INT64, `Float64` as DOUBLE,
//! `Boolean` as BOOLEAN, text as BYTE_ARRAY with the String logical type. polars, pandas
//! (pyarrow) and DuckDB read it as it is.

use std::sync::Arc;

use parquet::basic::{LogicalType, Repetition, Type as Physical};
use parquet::column::writer::ColumnWriter;
use parquet::data_type::ByteArray;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::Type;

use super::table::Column;

/// The definition levels (1 present, 0 null) and the present values of a column.
fn split<T: Clone>(v: &[Option<T>]) -> (Vec<i16>, Vec<T>) {
    let levels = v.iter().map(|x| i16::from(x.is_some())).collect();
    let values = v.iter().flatten().cloned().collect();
    (levels, values)
}

/// Writes the columns to `path`; errors as text naming the file.
pub fn write(path: &std::path::Path, columns: &[(String, Column)]) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let mut fields = Vec::with_capacity(columns.len());
    for (name, col) in columns {
        let (physical, logical) = match col {
            Column::Int(_) => (Physical::INT64, None),
            Column::Float(_) => (Physical::DOUBLE, None),
            Column::Bool(_) => (Physical::BOOLEAN, None),
            Column::Text(_) => (Physical::BYTE_ARRAY, Some(LogicalType::String)),
        };
        let field = Type::primitive_type_builder(name, physical)
            .with_repetition(Repetition::OPTIONAL)
            .with_logical_type(logical)
            .build()
            .map_err(|e| err(&e))?;
        fields.push(Arc::new(field));
    }
    let schema = Type::group_type_builder("sweep")
        .with_fields(fields)
        .build()
        .map_err(|e| err(&e))?;
    let file = std::fs::File::create(path).map_err(|e| err(&e))?;
    let props = Arc::new(WriterProperties::builder().build());
    let mut writer =
        SerializedFileWriter::new(file, Arc::new(schema), props).map_err(|e| err(&e))?;
    let mut group = writer.next_row_group().map_err(|e| err(&e))?;
    for (name, col) in columns {
        let Some(mut cw) = group.next_column().map_err(|e| err(&e))? else {
            return Err(err(&format!("no column writer for {name}")));
        };
        let written = match (cw.untyped(), col) {
            (ColumnWriter::Int64ColumnWriter(w), Column::Int(v)) => {
                let (levels, values) = split(v);
                w.write_batch(&values, Some(&levels), None)
            }
            (ColumnWriter::DoubleColumnWriter(w), Column::Float(v)) => {
                let (levels, values) = split(v);
                w.write_batch(&values, Some(&levels), None)
            }
            (ColumnWriter::BoolColumnWriter(w), Column::Bool(v)) => {
                let (levels, values) = split(v);
                w.write_batch(&values, Some(&levels), None)
            }
            (ColumnWriter::ByteArrayColumnWriter(w), Column::Text(v)) => {
                let (levels, values) = split(v);
                let bytes: Vec<ByteArray> = values
                    .into_iter()
                    .map(|s| ByteArray::from(s.into_bytes()))
                    .collect();
                w.write_batch(&bytes, Some(&levels), None)
            }
            _ => return Err(err(&format!("column {name}: writer of another type"))),
        };
        written.map_err(|e| err(&format!("column {name}: {e}")))?;
        cw.close().map_err(|e| err(&e))?;
    }
    group.close().map_err(|e| err(&e))?;
    writer.close().map_err(|e| err(&e))?;
    Ok(())
}
