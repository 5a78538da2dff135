//! Crash consistency of the persisted state: a representative sequence of saves (tool changes,
//! counters, settings, an erase) is cut by a power loss at every byte of every write and every
//! erase. After power comes back the store loads, each record is the one before the interrupted
//! save or the one it was writing (never anything else), and saving works again.

use embassy_futures::block_on;
use mmu_firmware::Instant;
use mmu_firmware::persist::{Counters, Snapshot, Store};
use mmu_firmware::unit::Lane;
use mmu_sim::flash::MemFlash;

/// Small pages, so the sequence wraps around the region and garbage collection is cut too.
const PAGE: usize = 256;
const PAGES: usize = 4;
const SLOTS: usize = 3;

type Flash = MemFlash<PAGE>;

fn store(flash: Flash) -> Store<Flash, SLOTS> {
    Store::new(flash, 0..(PAGE * PAGES) as u32).expect("a valid region")
}

/// One save of the sequence: the state to keep and the time it is kept at.
struct Step {
    snapshot: Snapshot<SLOTS>,
    at: Instant,
}

/// Tool changes back and forth with their counters, settings written by the printer, and
/// `X42` (`None`) before and after the region has wrapped.
fn sequence() -> Vec<Option<Step>> {
    let mut steps = Vec::new();
    let mut snapshot = Snapshot::<SLOTS> {
        lanes: [Lane::Parked; SLOTS],
        ..Snapshot::default()
    };
    let mut t = 0;
    for change in 0..24u16 {
        let (from, to) = (usize::from(change) % SLOTS, usize::from(change + 1) % SLOTS);
        for (slot, lane) in [
            (from, Lane::InHub),
            (from, Lane::Parked),
            (to, Lane::InHub),
            (to, Lane::Loaded),
        ] {
            snapshot.lanes[slot] = lane;
            t += 3_000;
            steps.push(Some(Step {
                snapshot: snapshot.clone(),
                at: Instant::from_millis(t),
            }));
        }
        snapshot.counters.tool_changes[to] += 1;
        snapshot.counters.fed_mm[to] += 380;
        if change % 4 == 1 {
            snapshot.counters.drive_errors += 1;
            snapshot.settings.clear();
            snapshot
                .settings
                .extend([(0x0b, 5 + change), (0x22, 360), (0x90, 2600)]);
        }
        if matches!(change, 6 | 17 | 22) {
            steps.push(None);
            snapshot = Snapshot::default();
        }
    }
    steps
}

/// Carry out `steps` on `flash`; the index of the step that failed (the power went), if any.
fn run(flash: &mut Store<Flash, SLOTS>, steps: &[Option<Step>]) -> Result<(), usize> {
    for (index, step) in steps.iter().enumerate() {
        let result = match step {
            Some(step) => block_on(flash.save(&step.snapshot, Some(step.at))).map(drop),
            None => block_on(flash.forget()),
        };
        result.map_err(|_| index)?;
    }
    Ok(())
}

#[test]
fn every_power_cut_leaves_the_old_or_the_new_record() {
    let steps = sequence();
    // The uncut run: what the flash holds after each step, and how many bytes it writes.
    let mut reference = store(Flash::new(PAGES));
    let mut states = vec![block_on(reference.load()).unwrap()];
    for (index, _) in steps.iter().enumerate() {
        run(&mut reference, &steps[index..=index]).unwrap();
        let mut copy = store(reference.flash().clone());
        states.push(block_on(copy.load()).unwrap());
    }
    let total =
        reference.flash().bytes_written as usize + reference.flash().erases.iter().sum::<u64>() as usize;
    assert!(
        reference.flash().max_erases() >= 2,
        "the sequence wraps the region"
    );

    let mut cuts = 0;
    for cut in 0..=total {
        let mut flash = Flash::new(PAGES);
        flash.cut_power_after(cut);
        let mut unit = store(flash);
        let Err(failed) = run(&mut unit, &steps) else {
            continue;
        };
        cuts += 1;
        let mut flash = unit.into_flash();
        flash.power_on();
        let mut rebooted = store(flash);
        let loaded = block_on(rebooted.load())
            .unwrap_or_else(|_| panic!("cut at byte {cut} (step {failed}): the store does not load"));
        let (before, after) = (&states[failed], &states[failed + 1]);
        assert!(
            loaded.lanes == before.lanes || loaded.lanes == after.lanes,
            "cut at byte {cut} (step {failed}): lanes {:?}, expected {:?} or {:?}",
            loaded.lanes,
            before.lanes,
            after.lanes
        );
        assert!(
            loaded.counters == before.counters || loaded.counters == after.counters,
            "cut at byte {cut} (step {failed}): counters {:?}",
            loaded.counters
        );
        assert!(
            loaded.settings == before.settings || loaded.settings == after.settings,
            "cut at byte {cut} (step {failed}): settings {:?}",
            loaded.settings
        );
        // The unit goes on: the rest of the sequence saves and loads back.
        run(&mut rebooted, &steps[failed..])
            .unwrap_or_else(|step| panic!("cut at byte {cut}: step {step} fails after the restart"));
        let mut last = store(rebooted.into_flash());
        assert_eq!(
            block_on(last.load()).unwrap(),
            states[steps.len()],
            "cut at byte {cut}"
        );
    }
    assert!(cuts > 1000, "{cuts} cut points");
}

#[test]
fn counters_are_written_at_a_bounded_rate_lanes_and_settings_at_once() {
    let mut unit = store(Flash::new(PAGES));
    let mut snapshot = Snapshot::<SLOTS>::default();
    let at = |ms| Some(Instant::from_millis(ms));
    snapshot.counters = Counters {
        drive_errors: 1,
        ..Counters::default()
    };
    assert_eq!(block_on(unit.save(&snapshot, at(0))), Ok(1));
    snapshot.counters.drive_errors = 2;
    assert!(
        !unit.save_due(&snapshot, Instant::from_millis(5_000)),
        "too soon for counters"
    );
    assert_eq!(block_on(unit.save(&snapshot, at(5_000))), Ok(0));
    snapshot.lanes[1] = Lane::Loaded;
    snapshot.settings.push((0x52, 2)).unwrap();
    assert!(
        unit.save_due(&snapshot, Instant::from_millis(5_001)),
        "lanes and settings go at once"
    );
    assert_eq!(block_on(unit.save(&snapshot, at(5_001))), Ok(2));
    assert_eq!(
        block_on(unit.save(&snapshot, at(10_000))),
        Ok(1),
        "counters after the period"
    );
    assert_eq!(
        block_on(unit.save(&snapshot, at(30_000))),
        Ok(0),
        "nothing changed"
    );
    snapshot.counters.drive_errors = 3;
    assert_eq!(
        block_on(unit.save(&snapshot, None)),
        Ok(1),
        "before a reset, at once"
    );
    let mut rebooted = store(unit.into_flash());
    assert_eq!(block_on(rebooted.load()).unwrap(), snapshot);
}
