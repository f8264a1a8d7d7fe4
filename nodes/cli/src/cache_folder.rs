//! Where a run keeps its disk cache.

/// The disk-cache folder a run uses and where that came from: `cache` (`--cache`), else
/// `$RELUME_CACHE` (set and not empty), else `.relume-cache` in the current folder; none with
/// `no_disk_cache`. The command line and the Python package both take it from here.
pub fn cache_dir(cache: Option<&std::path::Path>, no_disk_cache: bool) -> Option<(std::path::PathBuf, &'static str)> {
    if no_disk_cache {
        return None;
    }
    // Set but empty is unset: an empty folder name would put the cache's key folders in the
    // current folder.
    Some(match (cache, std::env::var_os("RELUME_CACHE").filter(|d| !d.is_empty())) {
        (Some(d), _) => (d.to_path_buf(), "from --cache"),
        (None, Some(d)) => (std::path::PathBuf::from(d), "from RELUME_CACHE"),
        (None, None) => (std::path::PathBuf::from(".relume-cache"), "the default"),
    })
}
