"""Puts the CCM's telemetry and a CAN message side by side in time.

Usage: python join_telemetry_can.py EXPORT_DIR   (an `aer-raspi export` folder)

Every table has `ts_us`, the time the Pi received the row (UTC). A message the car sends on
two buses (CCM_Status) has a row per bus at nearly the same time: pick one bus before
joining, or each telemetry packet meets whichever copy came last.
"""

import sys

import polars as pl

export = sys.argv[1]
telemetry = pl.read_parquet(f"{export}/parquet/telemetry.parquet").sort("ts_us")
status = (
    pl.read_parquet(f"{export}/parquet/can_ccm_status.parquet")
    .filter(pl.col("bus") == "can0")  # the vehicle bus's copy only
    .sort("ts_us")
)
# For each telemetry packet, the latest CCM_Status received at or before it, if it is at most
# 100 ms old (its cycle time).
joined = telemetry.join_asof(
    status, on="ts_us", strategy="backward", tolerance="100ms", suffix="_status"
)
print(joined.select("ts_us", "vehicle_state", "ccm_vehicle_state", "motor_speed").tail(3))
print(f"{joined.height} packets, {joined['ccm_vehicle_state'].null_count()} without a status")
