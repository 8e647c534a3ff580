//! The `user_cases` table: the definitions of user-defined cases, registered
//! in this process at start-up and when a client adds one.

use crate::db::sql;
use crate::store::error::StoreError;
use rusqlite::{params, Connection};
use tslg_method::cases::user::registry::{register, UserCaseDefinition};

/// Registers every stored case; one that no longer reads (a newer build
/// refusing it) is logged and left out.
pub fn register_stored(conn: &Connection) -> Result<(), StoreError> {
    let rows: Vec<(String, String, String, String)> = sql::all(
        conn,
        "SELECT name, file, table_name, table_text FROM user_cases ORDER BY name",
        [],
    )?;
    for (name, file, table_name, table) in rows {
        let definition = UserCaseDefinition {
            file,
            table_name,
            table,
        };
        if let Err(e) = register(definition) {
            tracing::error!(case = %name, error = %e, "a stored user-defined case does not read");
        }
    }
    Ok(())
}

/// Stores a registered case's definition (again, harmlessly, when the
/// same; a write).
pub fn insert(
    conn: &Connection,
    name: &str,
    definition: &UserCaseDefinition,
) -> Result<(), StoreError> {
    sql::execute(
        conn,
        "INSERT OR IGNORE INTO user_cases (name, file, table_name, table_text) \
         VALUES (?, ?, ?, ?)",
        params![
            name,
            definition.file,
            definition.table_name,
            definition.table
        ],
    )?;
    Ok(())
}

/// The stored definition of case `name`, for the plans workers read.
pub fn get(conn: &Connection, name: &str) -> Result<Option<UserCaseDefinition>, StoreError> {
    let row: Option<(String, String, String)> = sql::optional(
        conn,
        "SELECT file, table_name, table_text FROM user_cases WHERE name = ?",
        [name],
    )?;
    Ok(row.map(|(file, table_name, table)| UserCaseDefinition {
        file,
        table_name,
        table,
    }))
}
