//! The `user_cases` table: the definitions of user-defined cases, registered
//! in this process at start-up and when a client adds one.

use crate::error::ApiError;
use sqlx::SqlitePool;
use tslg_method::cases::user::registry::{register, UserCaseDefinition};

/// Registers every stored case; one that no longer reads (a newer build
/// refusing it) is logged and left out.
pub async fn register_stored(pool: &SqlitePool) -> Result<(), ApiError> {
    let rows: Vec<(String, String, String, String)> =
        sqlx::query_as("SELECT name, file, table_name, table_text FROM user_cases ORDER BY name")
            .fetch_all(pool)
            .await?;
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

/// Stores a registered case's definition (again, harmlessly, when the same).
pub async fn insert(
    pool: &SqlitePool,
    name: &str,
    definition: &UserCaseDefinition,
) -> Result<(), ApiError> {
    sqlx::query(
        "INSERT OR IGNORE INTO user_cases (name, file, table_name, table_text) \
         VALUES (?, ?, ?, ?)",
    )
    .bind(name)
    .bind(&definition.file)
    .bind(&definition.table_name)
    .bind(&definition.table)
    .execute(pool)
    .await?;
    Ok(())
}

/// The stored definition of case `name`, for the plans workers read.
pub async fn get(pool: &SqlitePool, name: &str) -> Result<Option<UserCaseDefinition>, ApiError> {
    let row: Option<(String, String, String)> =
        sqlx::query_as("SELECT file, table_name, table_text FROM user_cases WHERE name = ?")
            .bind(name)
            .fetch_optional(pool)
            .await?;
    Ok(row.map(|(file, table_name, table)| UserCaseDefinition {
        file,
        table_name,
        table,
    }))
}
