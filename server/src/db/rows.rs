//! Rows decoded into the API's types: a row becomes any `wire` type (or other serde type) by its
//! column names, through a JSON object of the values as either engine gives them (SQLite keeps
//! yes/no as 0/1; the `wire` rows read both). The rows are then defined once, in `wire`, which knows
//! no database.

use serde::de::DeserializeOwned;
use serde_json::{Map, Value};
use sqlx::any::{AnyRow, AnyTypeInfoKind};
use sqlx::{Column, FromRow, Row as _, ValueRef as _};

/// A row decoded as `T`; `query_as::<_, Row<T>>` and [`rows`] or [`row`] to unwrap.
pub struct Row<T>(pub T);

impl<'r, T: DeserializeOwned> FromRow<'r, AnyRow> for Row<T> {
    fn from_row(row: &'r AnyRow) -> sqlx::Result<Row<T>> {
        let mut object = Map::new();
        for (i, column) in row.columns().iter().enumerate() {
            let raw = row.try_get_raw(i)?;
            let value = if raw.is_null() {
                Value::Null
            } else {
                match raw.type_info().kind() {
                    AnyTypeInfoKind::Bool => Value::Bool(row.try_get(i)?),
                    AnyTypeInfoKind::SmallInt
                    | AnyTypeInfoKind::Integer
                    | AnyTypeInfoKind::BigInt => Value::from(row.try_get::<i64, _>(i)?),
                    AnyTypeInfoKind::Real | AnyTypeInfoKind::Double => {
                        Value::from(row.try_get::<f64, _>(i)?)
                    }
                    AnyTypeInfoKind::Text => Value::String(row.try_get(i)?),
                    other => {
                        return Err(sqlx::Error::ColumnDecode {
                            index: column.name().to_string(),
                            source: format!("a {other:?} value has no place in the API's rows")
                                .into(),
                        })
                    }
                }
            };
            object.insert(column.name().to_string(), value);
        }
        serde_json::from_value(Value::Object(object))
            .map(Row)
            .map_err(|e| sqlx::Error::Decode(format!("{}: {e}", std::any::type_name::<T>()).into()))
    }
}

/// The rows' values.
pub fn rows<T>(rows: Vec<Row<T>>) -> Vec<T> {
    rows.into_iter().map(|r| r.0).collect()
}

/// The row's value, if there is a row.
pub fn row<T>(row: Option<Row<T>>) -> Option<T> {
    row.map(|r| r.0)
}
