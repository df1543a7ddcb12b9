//! The file system's free space, for the retention budgets' free-space floor.

use std::path::Path;

/// Bytes an unprivileged writer can still use on the file system holding `path` (its folder
/// if `path` does not exist yet); `None` if it cannot be read.
#[cfg(unix)]
pub(crate) fn free_bytes(path: &Path) -> Option<u64> {
    let probe = if path.exists() {
        path
    } else {
        path.parent().filter(|p| !p.as_os_str().is_empty())?
    };
    let stats = rustix::fs::statvfs(probe).ok()?;
    Some(stats.f_bavail.saturating_mul(stats.f_frsize))
}

/// Not known off Unix: the floor is then never the reason to prune.
#[cfg(not(unix))]
pub(crate) fn free_bytes(_: &Path) -> Option<u64> {
    None
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_build_folder_has_some_free_space() {
        let free = super::free_bytes(std::path::Path::new(env!("CARGO_MANIFEST_DIR")));
        assert!(free.is_some_and(|bytes| bytes > 0));
    }
}
