//! A sweep's rows as typed columns (module docs of [`super`] give their order).
//!
//! A column's type follows from its non-null values: all integers, `Int64`; all numbers,
//! `Float64`; all booleans, `Boolean`; otherwise text (numbers and booleans written out).
//! `pyfoc.sweep` applies the same rule to its DataFrame.

use super::Row;

/// One value of a table.
#[derive(Clone, Debug, PartialEq)]
pub enum Cell {
    /// Missing, not applicable, or `NaN`.
    Null,
    /// A boolean.
    Bool(bool),
    /// A whole number.
    Int(i64),
    /// A real number (finite).
    Float(f64),
    /// Text.
    Text(String),
}

impl Cell {
    /// A JSON value as a cell (lists and objects as their JSON text).
    pub fn of_json(v: &serde_json::Value) -> Self {
        use serde_json::Value as J;
        match v {
            J::Null => Cell::Null,
            J::Bool(b) => Cell::Bool(*b),
            J::Number(n) => match n.as_i64() {
                Some(i) => Cell::Int(i),
                None => n.as_f64().map_or(Cell::Null, Cell::Float),
            },
            J::String(s) => Cell::Text(s.clone()),
            other => Cell::Text(other.to_string()),
        }
    }

    /// A TOML value as a cell (tables, arrays and dates as their TOML text).
    pub fn of_toml(v: &toml::Value) -> Self {
        match v {
            toml::Value::Boolean(b) => Cell::Bool(*b),
            toml::Value::Integer(i) => Cell::Int(*i),
            toml::Value::Float(f) if f.is_finite() => Cell::Float(*f),
            toml::Value::Float(_) => Cell::Null,
            toml::Value::String(s) => Cell::Text(s.clone()),
            other => Cell::Text(other.to_string()),
        }
    }

    fn text(&self) -> Option<String> {
        match self {
            Cell::Null => None,
            Cell::Bool(b) => Some(b.to_string()),
            Cell::Int(i) => Some(i.to_string()),
            Cell::Float(f) => Some(f.to_string()),
            Cell::Text(s) => Some(s.clone()),
        }
    }
}

/// A column's type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColumnKind {
    /// 64-bit integers.
    Int,
    /// 64-bit floats.
    Float,
    /// Booleans.
    Bool,
    /// UTF-8 text.
    Text,
}

/// One typed column; `None` is a null.
#[derive(Clone, Debug, PartialEq)]
pub enum Column {
    /// 64-bit integers.
    Int(Vec<Option<i64>>),
    /// 64-bit floats.
    Float(Vec<Option<f64>>),
    /// Booleans.
    Bool(Vec<Option<bool>>),
    /// Text.
    Text(Vec<Option<String>>),
}

/// The kind of a column of these cells (module docs).
pub fn kind_of(cells: &[&Cell]) -> ColumnKind {
    let mut ints = true;
    let mut nums = true;
    let mut bools = true;
    for c in cells {
        match c {
            Cell::Null => {}
            Cell::Int(_) => bools = false,
            Cell::Float(_) => {
                ints = false;
                bools = false;
            }
            Cell::Bool(_) => {
                ints = false;
                nums = false;
            }
            Cell::Text(_) => {
                ints = false;
                nums = false;
                bools = false;
            }
        }
    }
    if ints && nums && !bools {
        ColumnKind::Int
    } else if nums && !bools {
        ColumnKind::Float
    } else if bools && !ints {
        ColumnKind::Bool
    } else if ints && nums && bools {
        // Every cell null: a float column of nulls.
        ColumnKind::Float
    } else {
        ColumnKind::Text
    }
}

/// Cells typed as one column.
pub fn column_of(cells: &[&Cell]) -> Column {
    match kind_of(cells) {
        ColumnKind::Int => Column::Int(
            cells
                .iter()
                .map(|c| match c {
                    Cell::Int(i) => Some(*i),
                    _ => None,
                })
                .collect(),
        ),
        ColumnKind::Float => Column::Float(
            cells
                .iter()
                .map(|c| match c {
                    Cell::Int(i) => Some(*i as f64),
                    Cell::Float(f) => Some(*f),
                    _ => None,
                })
                .collect(),
        ),
        ColumnKind::Bool => Column::Bool(
            cells
                .iter()
                .map(|c| match c {
                    Cell::Bool(b) => Some(*b),
                    _ => None,
                })
                .collect(),
        ),
        ColumnKind::Text => Column::Text(cells.iter().map(|c| c.text()).collect()),
    }
}

/// The rows (sorted by index) as named columns: `index`, the varied paths (`paths`), `seed`,
/// every metric in order of first appearance, `error`.
pub fn columns(paths: &[String], rows: &[Row]) -> Vec<(String, Column)> {
    let mut rows: Vec<&Row> = rows.iter().collect();
    rows.sort_by_key(|r| r.index);
    let mut out = Vec::new();
    out.push((
        "index".to_string(),
        Column::Int(rows.iter().map(|r| Some(r.index as i64)).collect()),
    ));
    // A varied `seed` is the run's noise seed: the `seed` column.
    for p in paths.iter().filter(|p| p.as_str() != "seed") {
        let cells: Vec<Cell> = rows
            .iter()
            .map(|r| {
                r.values
                    .iter()
                    .find(|(k, _)| k == p)
                    .map_or(Cell::Null, |(_, v)| Cell::of_toml(v))
            })
            .collect();
        out.push((p.clone(), column_of(&cells.iter().collect::<Vec<_>>())));
    }
    out.push((
        "seed".to_string(),
        Column::Int(rows.iter().map(|r| Some(r.seed as i64)).collect()),
    ));
    let mut names: Vec<&str> = Vec::new();
    let mut known = std::collections::HashSet::new();
    for r in &rows {
        for (k, _) in &r.metrics {
            if known.insert(k.as_str()) {
                names.push(k);
            }
        }
    }
    let null = Cell::Null;
    for name in names {
        let cells: Vec<&Cell> = rows
            .iter()
            .map(|r| {
                r.metrics
                    .iter()
                    .find(|(k, _)| k == name)
                    .map_or(&null, |(_, c)| c)
            })
            .collect();
        out.push((name.to_string(), column_of(&cells)));
    }
    out.push((
        "error".to_string(),
        Column::Text(rows.iter().map(|r| r.error.clone()).collect()),
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_follow_the_non_null_values() {
        let k = |cells: &[Cell]| kind_of(&cells.iter().collect::<Vec<_>>());
        assert_eq!(k(&[Cell::Int(1), Cell::Null]), ColumnKind::Int);
        assert_eq!(k(&[Cell::Int(1), Cell::Float(0.5)]), ColumnKind::Float);
        assert_eq!(k(&[Cell::Bool(true), Cell::Null]), ColumnKind::Bool);
        assert_eq!(k(&[Cell::Bool(true), Cell::Int(1)]), ColumnKind::Text);
        assert_eq!(k(&[Cell::Text("a".into())]), ColumnKind::Text);
        assert_eq!(k(&[Cell::Null]), ColumnKind::Float);
    }
}
