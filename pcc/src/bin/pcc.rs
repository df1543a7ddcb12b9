#![no_std]
#![no_main]
use teensy4_panic as _;
#[rtic::app(device = teensy4_bsp, peripherals = true, dispatchers = [KPP])]
mod app {
    use teensy4_bsp::board;
    #[shared]
    struct Shared {}
    #[local]
    struct Local {}
    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let _b = board::t40(cx.device);
        (Shared {}, Local {})
    }
}
