//! The raw log's folder: segment files named by the time they were started, and the budget
//! that removes the oldest ones.

use std::path::{Path, PathBuf};
use std::time::Duration;

/// Segment files end with this.
pub(crate) const EXTENSION: &str = "aerraw";

/// The raw log's budget.
#[derive(Debug, Clone, PartialEq)]
pub struct Budget {
    /// The most the segments may take together.
    pub max_bytes: u64,
    /// Segments started longer ago than this go.
    pub max_age: Option<Duration>,
    /// Below this much free space on the folder's file system, the oldest segments go.
    pub min_free_bytes: u64,
}

/// The file name of a segment started at `start_us` (us since the epoch): names sort by time.
pub fn file_name(start_us: u64) -> String {
    format!("raw-{start_us:020}.{EXTENSION}")
}

/// When a segment was started, from its file name.
pub fn started_us(path: &Path) -> Option<u64> {
    let name = path.file_name()?.to_str()?;
    name.strip_prefix("raw-")?
        .strip_suffix(&format!(".{EXTENSION}"))?
        .parse()
        .ok()
}

/// The folder's segments, oldest first, with their sizes.
pub fn list(dir: &Path) -> Vec<(PathBuf, u64)> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut segments: Vec<(PathBuf, u64)> = entries
        .filter_map(Result::ok)
        .map(|entry| entry.path())
        .filter(|path| started_us(path).is_some())
        .filter_map(|path| {
            let len = std::fs::metadata(&path).ok()?.len();
            Some((path, len))
        })
        .collect();
    segments.sort();
    segments
}

/// Removes the oldest segments (never `current`) that are too old, and more while the folder
/// is over its size budget. Under the free-space floor, only segments started before
/// `kept_from_us` (this run's start) go, and only when removing them all could lift the free
/// space over the floor: deleting what cannot help would destroy the history and gain
/// nothing. Returns how many went.
pub fn prune(
    dir: &Path,
    budget: &Budget,
    current: Option<&Path>,
    kept_from_us: Option<u64>,
    now_us: u64,
    free_space: impl Fn(&Path) -> Option<u64>,
) -> u64 {
    let all = list(dir);
    // The current segment counts toward the size, and is never removed.
    let mut total: u64 = all.iter().map(|(_, len)| len).sum();
    let segments: Vec<(PathBuf, u64)> = all
        .into_iter()
        .filter(|(path, _)| current != Some(path.as_path()))
        .collect();
    let earlier = |path: &Path| {
        kept_from_us.is_none_or(|kept| started_us(path).is_some_and(|start| start < kept))
    };
    let freeable: u64 = segments
        .iter()
        .filter(|(path, _)| earlier(path))
        .map(|(_, len)| len)
        .sum();
    let free = free_space(dir);
    let reachable = free.is_some_and(|free| free.saturating_add(freeable) >= budget.min_free_bytes);
    let cutoff = budget
        .max_age
        .map(|age| now_us.saturating_sub(age.as_micros() as u64));
    let mut removed = 0;
    let mut freed = 0u64;
    for (path, len) in segments {
        let too_old = cutoff.is_some_and(|cutoff| started_us(&path).is_some_and(|t| t < cutoff));
        let over_size = total > budget.max_bytes;
        let under_floor = reachable
            && earlier(&path)
            && free.is_some_and(|free| free.saturating_add(freed) < budget.min_free_bytes);
        if !(too_old || over_size || under_floor) {
            break;
        }
        if std::fs::remove_file(&path).is_ok() {
            total = total.saturating_sub(len);
            freed = freed.saturating_add(len);
            removed += 1;
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_carry_the_start_time_and_sort_by_it() {
        let name = file_name(1_700_000_000_123_456);
        assert_eq!(name, "raw-00001700000000123456.aerraw");
        assert_eq!(started_us(Path::new(&name)), Some(1_700_000_000_123_456));
        assert_eq!(started_us(Path::new("raw-x.aerraw")), None);
        assert!(file_name(9) < file_name(10));
    }

    #[test]
    fn the_oldest_go_first_and_the_current_one_stays() {
        let dir = tempfile::tempdir().unwrap();
        let path = |t: u64| dir.path().join(file_name(t));
        for t in [1_000, 2_000, 3_000, 4_000] {
            std::fs::write(path(t), vec![0u8; 100]).unwrap();
        }
        std::fs::write(dir.path().join("notes.txt"), "not a segment").unwrap();
        let budget = Budget {
            max_bytes: 250,
            max_age: None,
            min_free_bytes: 0,
        };
        let no_floor = |_: &Path| None;
        assert_eq!(
            prune(dir.path(), &budget, Some(&path(1_000)), None, 0, no_floor),
            2
        );
        let left: Vec<PathBuf> = list(dir.path()).into_iter().map(|(p, _)| p).collect();
        assert_eq!(left, [path(1_000), path(4_000)], "the current one stays");
        // Age: everything started before the cutoff goes.
        let budget = Budget {
            max_bytes: u64::MAX,
            max_age: Some(Duration::from_micros(1_000)),
            min_free_bytes: 0,
        };
        assert_eq!(prune(dir.path(), &budget, None, None, 4_500, no_floor), 1);
        assert!(dir.path().join("notes.txt").exists());
    }

    #[test]
    fn the_floor_takes_only_earlier_runs_and_only_when_that_helps() {
        let dir = tempfile::tempdir().unwrap();
        let path = |t: u64| dir.path().join(file_name(t));
        for t in [1_000, 2_000, 3_000, 4_000] {
            std::fs::write(path(t), vec![0u8; 100]).unwrap();
        }
        let floor = Budget {
            max_bytes: u64::MAX,
            max_age: None,
            min_free_bytes: 1_000,
        };
        let this_run = Some(2_500);
        // Short by 250 bytes, the earlier run has 200: removing it cannot help, so it stays.
        assert_eq!(
            prune(dir.path(), &floor, None, this_run, 0, |_| Some(750)),
            0
        );
        assert_eq!(list(dir.path()).len(), 4);
        // Short by 150: the oldest two go, this run's stay.
        assert_eq!(
            prune(dir.path(), &floor, None, this_run, 0, |_| Some(850)),
            2
        );
        let left: Vec<PathBuf> = list(dir.path()).into_iter().map(|(p, _)| p).collect();
        assert_eq!(left, [path(3_000), path(4_000)]);
        // Short by 50 with nothing earlier left: nothing goes.
        assert_eq!(
            prune(dir.path(), &floor, None, this_run, 0, |_| Some(950)),
            0
        );
    }
}
