//! WDOG1's service: fed only while every task's heartbeat is fresh, so a stuck task resets
//! the CCM (with no torque: the inverter's own command timeout holds it at zero meanwhile).

use crate::Mono;
use crate::app::watchdog;
use crate::now_ms;
use aer_ccm::constants::WATCHDOG_CHECK_MS;
use aer_ccm::hw::feed_watchdog;
use rtic::Mutex;
use rtic_monotonics::imxrt::prelude::*;

pub(crate) async fn watchdog(mut cx: watchdog::Context<'_>) {
    loop {
        let now = now_ms();
        if cx
            .shared
            .supervisor
            .lock(|supervisor| supervisor.overdue(now))
            == 0
        {
            feed_watchdog(cx.local.wdog);
        }
        Mono::delay(u64::from(WATCHDOG_CHECK_MS).millis()).await;
    }
}
