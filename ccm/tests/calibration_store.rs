//! The saved calibration: two copies in flash, each with its CRC and the schema's EPK; start-up
//! loads the newest good one or the defaults and says which; a power cut at any byte of a save
//! leaves the previous copy loadable; saving only at standstill with the tractive system off.

use aer::calibration::{PAGE_LEN, VehicleState};
use aer_ccm::calibration::Calibration;
use aer_ccm::calibration::store::{
    CalibrationFlash, CalibrationStore, FlashError, RECORD_LEN, RamFlash, SaveError, Slot, Startup,
    crc32,
};
use proptest::prelude::*;

const EPK: &[u8] = b"AER test schema 0001";
const PARKED: VehicleState = VehicleState {
    moving: false,
    tractive_live: false,
};

/// A calibration other than the defaults (a lower launch slip target), as a page.
fn tuned(launch_target: f32) -> (Calibration, [u8; PAGE_LEN]) {
    let mut calibration = Calibration::DEFAULT;
    calibration.launch_slip_target = [launch_target; 4];
    (calibration, calibration.to_page())
}

#[test]
fn the_crc_is_crc32_ieee() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
}

#[test]
fn an_empty_flash_loads_the_defaults_and_says_none_is_saved() {
    let mut flash = RamFlash::default();
    let (_, loaded) = CalibrationStore::load(&mut flash, EPK);
    assert_eq!(loaded.startup, Startup::NoneSaved);
    assert_eq!(loaded.calibration, Calibration::DEFAULT);
    assert_eq!(
        loaded.startup.to_string(),
        "calibration: the schema's defaults (none saved)"
    );
}

#[test]
fn saves_alternate_slots_and_start_up_loads_the_newest() {
    let mut flash = RamFlash::default();
    let (mut store, _) = CalibrationStore::load(&mut flash, EPK);
    let (first, first_page) = tuned(0.05);
    let (second, second_page) = tuned(0.04);
    assert_eq!(
        store.save(&mut flash, &first_page, EPK, PARKED),
        Ok(Startup::Saved {
            slot: Slot::A,
            generation: 1
        })
    );
    let (_, loaded) = CalibrationStore::load(&mut flash, EPK);
    assert_eq!(loaded.calibration, first);
    assert_eq!(
        store.save(&mut flash, &second_page, EPK, PARKED),
        Ok(Startup::Saved {
            slot: Slot::B,
            generation: 2
        })
    );
    let (mut reloaded_store, loaded) = CalibrationStore::load(&mut flash, EPK);
    assert_eq!(loaded.calibration, second);
    assert_eq!(
        loaded.startup.to_string(),
        "calibration: saved copy B (generation 2)"
    );
    // After a restart, the next save goes over the older copy again.
    assert_eq!(
        reloaded_store.save(&mut flash, &first_page, EPK, PARKED),
        Ok(Startup::Saved {
            slot: Slot::A,
            generation: 3
        })
    );
    assert_eq!(CalibrationStore::load(&mut flash, EPK).1.calibration, first);
}

#[test]
fn saving_is_refused_while_moving_or_with_the_tractive_system_live() {
    let mut flash = RamFlash::default();
    let (mut store, _) = CalibrationStore::load(&mut flash, EPK);
    let (_, page) = tuned(0.05);
    for state in [
        VehicleState {
            moving: true,
            tractive_live: false,
        },
        VehicleState {
            moving: false,
            tractive_live: true,
        },
    ] {
        assert_eq!(
            store.save(&mut flash, &page, EPK, state),
            Err(SaveError::NotAllowedNow)
        );
    }
    assert_eq!(
        CalibrationStore::load(&mut flash, EPK).1.startup,
        Startup::NoneSaved,
        "a refused save must not touch the flash"
    );
}

#[test]
fn a_corrupt_only_copy_loads_the_defaults_and_says_so() {
    let mut flash = RamFlash::default();
    let (mut store, _) = CalibrationStore::load(&mut flash, EPK);
    let (_, page) = tuned(0.05);
    store.save(&mut flash, &page, EPK, PARKED).unwrap();
    flash.slot_mut(Slot::A)[80] ^= 0x10;
    let (_, loaded) = CalibrationStore::load(&mut flash, EPK);
    assert_eq!(loaded.startup, Startup::Corrupt);
    assert_eq!(loaded.calibration, Calibration::DEFAULT);
    assert_eq!(
        loaded.startup.to_string(),
        "calibration: the schema's defaults (saved copy corrupt)"
    );
}

#[test]
fn a_corrupt_newest_copy_falls_back_to_the_older_one() {
    let mut flash = RamFlash::default();
    let (mut store, _) = CalibrationStore::load(&mut flash, EPK);
    let (older, older_page) = tuned(0.05);
    let (_, newer_page) = tuned(0.04);
    store.save(&mut flash, &older_page, EPK, PARKED).unwrap();
    store.save(&mut flash, &newer_page, EPK, PARKED).unwrap();
    flash.slot_mut(Slot::B)[RECORD_LEN - 1] ^= 0xFF;
    let (_, loaded) = CalibrationStore::load(&mut flash, EPK);
    assert_eq!(loaded.calibration, older);
    assert_eq!(
        loaded.startup,
        Startup::Saved {
            slot: Slot::A,
            generation: 1
        }
    );
}

#[test]
fn a_copy_of_another_schema_is_not_loaded_and_not_overwritten_first() {
    let mut flash = RamFlash::default();
    let (mut store, _) = CalibrationStore::load(&mut flash, b"AER another schema");
    let (_, page) = tuned(0.05);
    store
        .save(&mut flash, &page, b"AER another schema", PARKED)
        .unwrap();
    let (mut store, loaded) = CalibrationStore::load(&mut flash, EPK);
    assert_eq!(loaded.startup, Startup::OtherSchema);
    assert_eq!(loaded.calibration, Calibration::DEFAULT);
    // The new firmware's first save goes to the other slot, so the old copy survives a cut.
    assert_eq!(
        store.save(&mut flash, &page, EPK, PARKED),
        Ok(Startup::Saved {
            slot: Slot::B,
            generation: 2
        })
    );
}

#[test]
fn a_copy_with_values_the_ccm_refuses_loads_the_defaults() {
    let mut flash = RamFlash::default();
    let (mut store, _) = CalibrationStore::load(&mut flash, EPK);
    // Within the schema's limits each, but APPS1 would barely move (the sensor check).
    let mut calibration = Calibration::DEFAULT;
    calibration.apps1_v = [1.0, 1.05];
    store
        .save(&mut flash, &calibration.to_page(), EPK, PARKED)
        .unwrap();
    let (_, loaded) = CalibrationStore::load(&mut flash, EPK);
    assert_eq!(loaded.startup, Startup::OutOfLimits);
    assert_eq!(loaded.calibration, Calibration::DEFAULT);
}

/// A flash that loses power after `budget` programmed bytes: the byte being programmed keeps
/// only some of its cleared bits, and nothing after it is written.
struct CutFlash {
    inner: RamFlash,
    budget: usize,
    erase_cut: bool,
    torn_bits: u8,
}

impl CalibrationFlash for CutFlash {
    fn read(&mut self, slot: Slot, offset: usize, out: &mut [u8]) -> Result<(), FlashError> {
        self.inner.read(slot, offset, out)
    }

    fn erase(&mut self, slot: Slot) -> Result<(), FlashError> {
        if self.erase_cut {
            // Cut mid-erase: half the sector is erased, the rest keeps its old bytes.
            self.inner.slot_mut(slot)[..RECORD_LEN / 2].fill(0xFF);
            return Err(FlashError::Device);
        }
        self.inner.erase(slot)
    }

    fn program(&mut self, slot: Slot, offset: usize, data: &[u8]) -> Result<(), FlashError> {
        let take = data.len().min(self.budget);
        self.inner.program(slot, offset, &data[..take])?;
        self.budget -= take;
        if take < data.len() {
            let torn = data[take] | self.torn_bits;
            self.inner.program(slot, offset + take, &[torn])?;
            return Err(FlashError::Device);
        }
        Ok(())
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Whatever byte of the second save the power fails at, start-up loads the first copy.
    #[test]
    fn a_power_cut_during_a_save_leaves_the_previous_copy_loadable(
        budget in 0..RECORD_LEN,
        torn_bits in any::<u8>(),
        erase_cut in proptest::bool::weighted(0.1),
    ) {
        let mut flash = RamFlash::default();
        let (mut store, _) = CalibrationStore::load(&mut flash, EPK);
        let (first, first_page) = tuned(0.05);
        let (_, second_page) = tuned(0.04);
        store.save(&mut flash, &first_page, EPK, PARKED).unwrap();
        store.save(&mut flash, &second_page, EPK, PARKED).unwrap();
        let (third, third_page) = tuned(0.03);
        let mut cut = CutFlash { inner: flash, budget, erase_cut, torn_bits };
        // The third save goes over slot A (the first copy): B, the second, must survive.
        let (mut store, loaded) = CalibrationStore::load(&mut cut, EPK);
        prop_assert_eq!(loaded.startup, Startup::Saved { slot: Slot::B, generation: 2 });
        let result = store.save(&mut cut, &third_page, EPK, PARKED);
        prop_assert!(result.is_err());
        let (_, after) = CalibrationStore::load(&mut cut.inner, EPK);
        prop_assert_ne!(after.calibration, first);
        if after.startup == (Startup::Saved { slot: Slot::A, generation: 3 }) {
            // Only when the torn byte happened to be complete: the record is whole.
            prop_assert_eq!(after.calibration, third);
        } else {
            prop_assert_eq!(after.startup, Startup::Saved { slot: Slot::B, generation: 2 });
            prop_assert_ne!(after.calibration, third);
        }
    }

    /// The newest copy wins across the generation counter's wrap.
    #[test]
    fn generations_compare_across_the_wrap(start in any::<u32>()) {
        let mut flash = RamFlash::default();
        let (_, older_page) = tuned(0.05);
        let (newer, newer_page) = tuned(0.04);
        // Write two records by hand with generations `start` and `start + 1`.
        write_record(&mut flash, Slot::B, start, &older_page);
        write_record(&mut flash, Slot::A, start.wrapping_add(1), &newer_page);
        let (_, loaded) = CalibrationStore::load(&mut flash, EPK);
        prop_assert_eq!(loaded.calibration, newer);
        prop_assert_eq!(loaded.startup, Startup::Saved { slot: Slot::A, generation: start.wrapping_add(1) });
    }
}

/// Writes a record as the store does, at a chosen generation, through a fresh store whose
/// newest copy is set by saving once into a scratch flash.
fn write_record(flash: &mut RamFlash, slot: Slot, generation: u32, page: &[u8; PAGE_LEN]) {
    let mut scratch = RamFlash::default();
    let (mut store, _) = CalibrationStore::load(&mut scratch, EPK);
    store.save(&mut scratch, page, EPK, PARKED).unwrap();
    let bytes = *scratch.slot_mut(Slot::A);
    let mut record = bytes;
    record[4..8].copy_from_slice(&generation.to_le_bytes());
    let crc = crc32(&record[..RECORD_LEN - 4]);
    record[RECORD_LEN - 4..RECORD_LEN].copy_from_slice(&crc.to_le_bytes());
    *flash.slot_mut(slot) = record;
}

fn drain<const N: usize>(log: &mut aer_console::LogBuffer<N>) -> Vec<String> {
    let mut bytes = vec![0u8; N];
    let taken = log.peek(&mut bytes);
    log.consume(taken);
    String::from_utf8_lossy(&bytes[..taken])
        .lines()
        .map(str::to_owned)
        .collect()
}

/// Records a pedal (and brakes) at rest and fully pressed, as `cal rest` and `cal full` do.
fn measured_pedals(
    rest: [f32; 2],
    full: [f32; 2],
    brakes: [f32; 2],
) -> aer_ccm::calibration::BenchRecorder {
    use aer_ccm::calibration::{BenchPoint, BenchRecorder, BenchSample};
    let mut recorder = BenchRecorder::default();
    for (point, pedals) in [(BenchPoint::Rest, rest), (BenchPoint::Full, full)] {
        recorder.start(point);
        while recorder.recording() {
            recorder.sample(&BenchSample {
                pedals: pedals.map(Some),
                brakes,
                shocks: [5.0; 4],
            });
        }
    }
    recorder
}

#[test]
fn the_bring_up_saves_what_it_measured_over_the_tuned_values_and_loads_it_back() {
    use aer_ccm::calibration::measured::{MEASURED, SOURCE};
    use aer_ccm::calibration::{BenchRecorder, SensorCalibration};
    use aer_ccm::console::bringup::{cal_erase, cal_load, cal_save};
    let mut log = aer_console::LogBuffer::<4096>::new();
    let mut flash = RamFlash::default();
    let file = MEASURED.applied_to(Calibration::DEFAULT);
    let file_crc = crc32(&file.to_page());
    assert_eq!(cal_load(&mut log, &mut flash, MEASURED, SOURCE, EPK), 0);
    // Nothing measured yet: nothing to save (the defaults never overwrite a copy).
    assert_eq!(
        cal_save(
            &mut log,
            &mut flash,
            &BenchRecorder::default(),
            MEASURED,
            EPK,
            false
        ),
        0
    );
    // A tuner's save over XCP: a tuned gain in copy A.
    let tuned = Calibration {
        traction_kp: 650.0,
        ..file
    };
    let (mut store, _) = CalibrationStore::load(&mut flash, EPK);
    store
        .save(&mut flash, &tuned.to_page(), EPK, PARKED)
        .expect("saved");
    // The bench measures the pedal and saves: refused while live, then copy B with the
    // tuned gain kept.
    let recorder = measured_pedals([0.512, 0.771], [2.793, 4.187], [0.508, 0.514]);
    assert_eq!(
        cal_save(&mut log, &mut flash, &recorder, MEASURED, EPK, true),
        0
    );
    assert_eq!(
        cal_save(&mut log, &mut flash, &recorder, MEASURED, EPK, false),
        0
    );
    let (_, loaded) = CalibrationStore::load(&mut flash, EPK);
    assert_eq!(
        loaded.startup,
        Startup::Saved {
            slot: Slot::B,
            generation: 2
        }
    );
    assert_eq!(loaded.calibration.traction_kp, 650.0, "the tuning is kept");
    let sensors = SensorCalibration::of(&loaded.calibration);
    let near = |a: f32, b: f32| (a - b).abs() < 1e-4;
    assert!(near(sensors.pedals.apps1.0, 0.512) && near(sensors.pedals.apps1.1, 2.793));
    assert!(near(sensors.brakes.rear_zero_v, 0.514));
    let saved_crc = crc32(&loaded.calibration.to_page());
    assert_eq!(cal_load(&mut log, &mut flash, MEASURED, SOURCE, EPK), 0);
    // A refused measurement saves nothing.
    let refused = measured_pedals([0.2, 0.771], [2.793, 4.187], [0.508, 0.514]);
    assert_eq!(
        cal_save(&mut log, &mut flash, &refused, MEASURED, EPK, false),
        0
    );
    assert_eq!(
        CalibrationStore::load(&mut flash, EPK).1.startup,
        Startup::Saved {
            slot: Slot::B,
            generation: 2
        }
    );
    // `cal erase` goes back to the file; a torn copy is named.
    assert_eq!(cal_erase(&mut log, &mut flash, EPK, true), 0);
    assert_eq!(cal_erase(&mut log, &mut flash, EPK, false), 0);
    assert_eq!(cal_load(&mut log, &mut flash, MEASURED, SOURCE, EPK), 0);
    let (mut store, _) = CalibrationStore::load(&mut flash, EPK);
    store
        .save(&mut flash, &tuned.to_page(), EPK, PARKED)
        .expect("saved");
    flash.slot_mut(Slot::A)[20] ^= 1;
    assert_eq!(cal_load(&mut log, &mut flash, MEASURED, SOURCE, EPK), 0);
    assert_eq!(
        drain(&mut log),
        [
            format!("calibration: ccm/calibration.toml's sensors ({SOURCE}) on the schema's defaults, checksum 0x{file_crc:08X}; no copy saved"),
            "not saved: nothing measured this session (`cal rest` and `cal full`, or `cal shock` for every sensor's two ends, first)".to_owned(),
            "not saved: only at standstill with the tractive system off".to_owned(),
            format!("saved as copy B (generation 2), checksum 0x{saved_crc:08X}: the pedal and brake sensors measured now, over copy A (generation 1); every other value as it was"),
            format!("calibration: saved copy B (generation 2), checksum 0x{saved_crc:08X}; a saved copy wins over ccm/calibration.toml"),
            "not saved: the measurement was REFUSED (APPS1 at rest reads 0.200 V, outside its valid band 0.330-2.970 V (a sensor fault there)); measure again".to_owned(),
            "not erased: only with the tractive system off".to_owned(),
            "erased both saved copies: start-up now runs ccm/calibration.toml's sensors on the schema's defaults (`cal load` says so)".to_owned(),
            format!("calibration: ccm/calibration.toml's sensors ({SOURCE}) on the schema's defaults, checksum 0x{file_crc:08X}; no copy saved"),
            format!("calibration: ccm/calibration.toml's sensors ({SOURCE}) on the schema's defaults, checksum 0x{file_crc:08X}; the saved copy is corrupt"),
        ]
    );
}
