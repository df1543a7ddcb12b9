//! Nothing but tests (`tests/`): the Pi service and the dashboard, end to end through a real
//! broker. The two applications meet only here.
