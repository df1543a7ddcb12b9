//! What the PCC does when it fails itself (issue 12): a control loop that hangs or panics
//! stops servicing the watchdog, the PCC restarts with AIR+ open, and after a
//! watchdog restart it stays in ERROR ("undefined state") until it is power-cycled.
//!
//! The watchdog itself (WDOG1, 0.5 s) and the panic handler are hardware; here a model of
//! the watchdog is driven by the library's servicing policy, as the firmware drives WDOG1.

use aer::can::PccStatus;
use aer_pcc::measurement::Pulses;
use aer_pcc::watchdog::{LoopMonitor, reset_by_watchdog};
use aer_pcc::{Inputs, Precharge, PrechargeConfig, Relays, State, TASK_PERIOD_MS};

/// WDOG1 as the firmware sets it up: 0.5 s without service restarts the chip.
const WATCHDOG_TIMEOUT_MS: u32 = 500;

/// Healthy inputs for a pack at 400 V with the tractive system at `tractive_v`.
fn inputs(now_ms: u32, tractive_v: f32) -> Inputs {
    Inputs {
        now_ms,
        accumulator_v: 400.0,
        tractive_v,
        raw_v: [400.0, tractive_v],
        bms_last_seen_ms: Some(now_ms),
        charger_safety: false,
        pulses: [Pulses::Live; 2],
        resistor_c: [Some(25.0); 2],
    }
}

/// The PCC's control loop with the watchdog; `hang_from_ms` stops the loop there.
struct Board {
    pcc: Precharge,
    health: LoopMonitor,
    serviced_ms: u32,
    relays: Relays,
    restarts: u32,
}

impl Board {
    fn new() -> Self {
        Self {
            pcc: Precharge::new(PrechargeConfig::CAR, 0),
            health: LoopMonitor::new(TASK_PERIOD_MS),
            serviced_ms: 0,
            relays: Relays::ALL_OPEN,
            restarts: 0,
        }
    }

    /// One millisecond: the loop runs every 10 ms unless hung; the watchdog restarts the
    /// board when unserviced for its timeout.
    fn tick(&mut self, now_ms: u32, hung: bool, tractive_v: f32) {
        if !hung && now_ms % TASK_PERIOD_MS == 0 {
            self.relays = self.pcc.step(&inputs(now_ms, tractive_v));
            if self.health.step_completed(now_ms * 1_000) {
                self.serviced_ms = now_ms;
            }
        }
        if now_ms - self.serviced_ms > WATCHDOG_TIMEOUT_MS {
            // Reset: pins back to inputs (the board's pull-downs open the relays), then the
            // firmware starts and reads SRC_SRSR.
            self.relays = Relays::ALL_OPEN;
            let srsr = 1 << 4;
            assert!(reset_by_watchdog(srsr));
            self.pcc = Precharge::after_watchdog_reset(PrechargeConfig::CAR, now_ms);
            self.health = LoopMonitor::new(TASK_PERIOD_MS);
            self.serviced_ms = now_ms;
            self.restarts += 1;
        }
    }
}

#[test]
fn a_hang_online_releases_air_plus_within_the_watchdog_timeout() {
    // Before: no watchdog; a hung loop kept its outputs for ever. AIR+ is the only output,
    // high only in ONLINE and CHARGING: hang there.
    let mut board = Board::new();
    let mut t = 0;
    // The hardware starts precharging at 0.3 s: 5 % at first, 90 % inside the time window.
    let mut started = None;
    while board.pcc.state() != State::Online {
        t += 1;
        // A ramp that reaches 90 % of the pack 8.55 s after the rise, inside the window.
        let tractive_v = match started {
            Some(at) => (380.0 * (t - at) as f32 / 9_500.0).clamp(20.0, 380.0),
            _ if t > 300 => 20.0,
            _ => 0.0,
        };
        board.tick(t, false, tractive_v);
        if started.is_none() && board.pcc.state() == State::Precharge {
            started = Some(t);
        }
        assert!(t < 20_000, "reaches ONLINE");
    }
    assert!(board.relays.air_plus);
    let hung_at = t;
    let mut closed_until = hung_at;
    for now in hung_at + 1..hung_at + 2_000 {
        board.tick(now, now < hung_at + 1_500, 380.0);
        if !board.relays.all_open() {
            closed_until = now;
        }
    }
    assert!(board.restarts >= 1, "the watchdog restarted the board");
    assert!(
        closed_until - hung_at <= WATCHDOG_TIMEOUT_MS + TASK_PERIOD_MS,
        "AIR+ held {} ms into the hang",
        closed_until - hung_at
    );
    assert_eq!(board.pcc.state(), State::Error, "and it stays off");
}

#[test]
fn after_a_watchdog_restart_the_pcc_stays_in_error_until_a_power_cycle() {
    let mut pcc = Precharge::after_watchdog_reset(PrechargeConfig::CAR, 0);
    assert_eq!(pcc.state(), State::Error);
    assert!(pcc.relays().all_open());
    // Everything healthy for a minute: still ERROR, nothing closes.
    for now in (10..60_000).step_by(10) {
        let relays = pcc.step(&inputs(now, 0.0));
        assert!(relays.all_open(), "t = {now}");
    }
    assert_eq!(pcc.state(), State::Error);
    let status: PccStatus = pcc.status();
    assert!(
        status.pcc_error_undefined_state,
        "the status frame says why"
    );
    assert!(pcc.errors().needs_reset());
}

#[test]
fn a_loop_that_runs_late_does_not_service_the_watchdog() {
    let mut health = LoopMonitor::new(TASK_PERIOD_MS);
    assert!(health.step_completed(0));
    // A loop starved by an interrupt storm: steps 50 ms apart.
    let serviced = (1..=20)
        .filter(|k| health.step_completed(k * 50_000))
        .count();
    assert_eq!(
        serviced, 0,
        "never serviced, so the watchdog restarts the PCC"
    );
}
