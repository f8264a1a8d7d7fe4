//! Graph format migrations: explicit functions that upgrade an older document in place.

use crate::ron::Ron;

/// Upgrades a document of version `from` to `from + 1`.
pub struct Migration {
    pub from: u32,
    pub apply: fn(&mut Ron) -> Result<(), String>,
}

/// The migrations this build knows. Version 1 is the first format, so there are none yet;
/// a format change adds one here (and a test that an old file still loads).
pub const MIGRATIONS: &[Migration] = &[];

/// Applies migrations until the document is at `target`.
pub(crate) fn upgrade(doc: &mut Ron, mut version: u32, target: u32, migrations: &[Migration]) -> Result<(), String> {
    while version < target {
        let m = migrations.iter().find(|m| m.from == version).ok_or_else(|| {
            format!("graph format version {version} is not supported (this relume reads {target}, and no migration from {version} exists)")
        })?;
        (m.apply)(doc).map_err(|e| format!("migrating from version {version}: {e}"))?;
        version += 1;
    }
    Ok(())
}
