//! A LeRobot parquet file as rows of the few columns the importer reads (the `parquet` crate's
//! record reader, no Arrow): integers, numbers and lists of numbers.
use super::error::ImportError;
use parquet::file::reader::{FileReader, SerializedFileReader};
use parquet::record::Field;
use parquet::schema::types::Type;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// One value of a row.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Cell {
    Int(i64),
    Num(f64),
    /// A list of numbers; a null element is NaN (reported as non-finite).
    Vector(Vec<f64>),
    Null,
    /// Any other parquet value, by its type's name.
    Other(String),
}

impl Cell {
    fn of(field: &Field) -> Cell {
        match field {
            Field::Null => Cell::Null,
            Field::Byte(v) => Cell::Int(i64::from(*v)),
            Field::Short(v) => Cell::Int(i64::from(*v)),
            Field::Int(v) => Cell::Int(i64::from(*v)),
            Field::Long(v) => Cell::Int(*v),
            Field::UByte(v) => Cell::Int(i64::from(*v)),
            Field::UShort(v) => Cell::Int(i64::from(*v)),
            Field::UInt(v) => Cell::Int(i64::from(*v)),
            Field::ULong(v) => i64::try_from(*v).map_or(Cell::Num(*v as f64), Cell::Int),
            Field::Float16(v) => Cell::Num(f64::from(f32::from(*v))),
            Field::Float(v) => Cell::Num(f64::from(*v)),
            Field::Double(v) => Cell::Num(*v),
            Field::ListInternal(list) => {
                let mut out = Vec::with_capacity(list.len());
                for element in list.elements() {
                    match Cell::of(element) {
                        Cell::Int(v) => out.push(v as f64),
                        Cell::Num(v) => out.push(v),
                        Cell::Null => out.push(f64::NAN),
                        other => return Cell::Other(format!("a list of {}", other.kind())),
                    }
                }
                Cell::Vector(out)
            }
            Field::Str(_) => Cell::Other("text".into()),
            other => Cell::Other(format!("{other:?}").chars().take(40).collect()),
        }
    }

    /// What the value is, for error messages.
    pub(super) fn kind(&self) -> String {
        match self {
            Cell::Int(_) => "an integer".into(),
            Cell::Num(_) => "a number".into(),
            Cell::Vector(v) => format!("a list of {} numbers", v.len()),
            Cell::Null => "null".into(),
            Cell::Other(what) => what.clone(),
        }
    }

    /// The value as an integer (episode and frame indices).
    pub(super) fn int(&self) -> Option<i64> {
        match self {
            Cell::Int(v) => Some(*v),
            _ => None,
        }
    }

    /// The value as a number (timestamps).
    pub(super) fn num(&self) -> Option<f64> {
        match self {
            Cell::Int(v) => Some(*v as f64),
            Cell::Num(v) => Some(*v),
            _ => None,
        }
    }

    /// The value as a vector (state and action; a lone number is a vector of one).
    pub(super) fn vector(self) -> Option<Vec<f64>> {
        match self {
            Cell::Vector(v) => Some(v),
            Cell::Num(v) => Some(vec![v]),
            Cell::Int(v) => Some(vec![v as f64]),
            _ => None,
        }
    }
}

/// The rows of `columns` (in that order) of one parquet file.
pub(super) struct Table {
    pub path: PathBuf,
    pub rows: Vec<Vec<Cell>>,
}

/// Reads `columns` of the parquet file `path`; a column it lacks is [`ImportError::MissingKey`].
pub(super) fn read(path: &Path, columns: &[&str]) -> Result<Table, ImportError> {
    let parquet_error = |e: parquet::errors::ParquetError| ImportError::Parquet {
        path: path.to_path_buf(),
        problem: e.to_string(),
    };
    let file = std::fs::File::open(path).map_err(|e| ImportError::File {
        path: path.to_path_buf(),
        problem: format!("cannot open: {e}"),
    })?;
    let reader = SerializedFileReader::new(file).map_err(parquet_error)?;
    let schema = reader.metadata().file_metadata().schema();
    let fields = schema.get_fields();
    let mut projected = Vec::with_capacity(columns.len());
    for &column in columns {
        let field =
            fields
                .iter()
                .find(|f| f.name() == column)
                .ok_or_else(|| ImportError::MissingKey {
                    path: path.to_path_buf(),
                    key: column.to_string(),
                    found: fields.iter().map(|f| f.name().to_string()).collect(),
                })?;
        projected.push(Arc::clone(field));
    }
    let projection = Type::group_type_builder(schema.name())
        .with_fields(projected)
        .build()
        .map_err(parquet_error)?;
    let mut rows = Vec::new();
    for row in reader
        .get_row_iter(Some(projection))
        .map_err(parquet_error)?
    {
        let row = row.map_err(parquet_error)?;
        let mut cells = vec![Cell::Null; columns.len()];
        for (name, field) in row.get_column_iter() {
            if let Some(i) = columns.iter().position(|c| c == name) {
                cells[i] = Cell::of(field);
            }
        }
        rows.push(cells);
    }
    Ok(Table {
        path: path.to_path_buf(),
        rows,
    })
}
