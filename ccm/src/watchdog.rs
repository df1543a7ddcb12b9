//! Watchdog supervisor: every monitored task beats a heartbeat; the hardware watchdog (1 s)
//! is fed only while every heartbeat is younger than 100 ms, so a stalled task resets the
//! CCM.

/// The tasks the supervisor watches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Task {
    /// 1 kHz sensor sampling (APPS, brakes).
    Sensors = 0,
    /// 100 Hz vehicle control.
    Control = 1,
    /// Inverter commands.
    Inverter = 2,
    /// Telemetry.
    Telemetry = 3,
}

impl Task {
    /// Every task.
    pub const ALL: [Self; 4] = [
        Self::Sensors,
        Self::Control,
        Self::Inverter,
        Self::Telemetry,
    ];
}

/// Longest a heartbeat may be stale (ms).
pub const HEARTBEAT_LIMIT_MS: u32 = 100;

/// Heartbeats of the watched tasks.
#[derive(Debug, Clone, Default)]
pub struct Supervisor {
    beats: [Option<u32>; 4],
}

impl Supervisor {
    /// Records that `task` ran at `now_ms`.
    pub fn beat(&mut self, task: Task, now_ms: u32) {
        if let Some(slot) = self.beats.get_mut(task as usize) {
            *slot = Some(now_ms);
        }
    }

    /// Bitmask of overdue tasks (bit = `Task as u8`); 0 means feed the watchdog.
    pub fn overdue(&self, now_ms: u32) -> u8 {
        Task::ALL.iter().fold(0, |mask, task| {
            let fresh = self
                .beats
                .get(*task as usize)
                .copied()
                .flatten()
                .is_some_and(|at| now_ms.wrapping_sub(at) <= HEARTBEAT_LIMIT_MS);
            if fresh { mask } else { mask | 1 << *task as u8 }
        })
    }
}
