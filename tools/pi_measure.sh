# Shared by the Pi service's measurement scripts (source it): a configuration in WORK_DIR
# with the store and raw log there and no broker to reach, so only the disk is measured.
# usage: measure_config DIR  ->  writes DIR/cfg.toml
measure_config() {
  cat > "$1/cfg.toml" <<EOT
car_id = "car1"
[store]
path = "$1/store.sqlite"
[raw_log]
dir = "$1/raw"
[broker]
embedded = false
[mqtt]
port = 9
EOT
}
