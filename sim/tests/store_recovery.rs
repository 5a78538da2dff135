//! A store that cannot be stuck: a torn page erase brings back no old state and never makes the
//! save loop erase in circles; `X42` and a damaged or wiped store keep the unit's identity
//! (register 0x52, the version an MK3S checks); a flash that fails is retried with pauses, its
//! trouble reported once, and the erase rate stays bounded whatever the flash does.

use mmu_firmware::persist::{ERASE_BURST, ERASES_PER_HOUR, FULL_CHECK_MS, Health};
use mmu_firmware::unit::Lane;
use mmu_firmware::{BoardAction, Instant};
use mmu_protocol::{Request, RequestCode};
use mmu_sim::cut::{Action, Flash, Plan, Unit, study};
use mmu_sim::flash::CutModel;

const PAGES: usize = 3;

fn unit() -> Unit {
    Unit::boot(Flash::new(PAGES), PAGES, Instant::ZERO)
}

/// What `S2` answers (the revision the printer checks).
fn revision(unit: &mut Unit) -> String {
    unit.ask(Request::new(RequestCode::Version, 2)).0
}

/// The study's finding, seed 4: a torn erase during `X42` on 4 pages made every later save fail,
/// and the save loop erased a page at every 1 ms step (1000 erases in a second); other torn
/// erases brought stale lanes and settings back (lanes `[Parked, Unknown, Unknown]` came back as
/// `[InHub, AtFsensor, AtFsensor]`). Every torn page erase of 8 lives of 800 actions.
#[test]
fn a_torn_page_erase_brings_back_no_old_state_and_never_sticks_the_store() {
    let (mut cuts, mut failures) = (0, Vec::new());
    for seed in 1..=8 {
        let plan = Plan {
            erases_only: true,
            check_every_save: false,
            models: vec![CutModel::Torn, CutModel::TornUnreadable],
            ..Plan::every_cut(4, 800)
        };
        let report = study(seed, &plan);
        cuts += report.cuts.iter().sum::<usize>();
        failures.extend(report.failures);
    }
    assert!(cuts >= 100, "{cuts} erases cut");
    assert!(
        failures.is_empty(),
        "{} failures of {cuts} cuts:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn x42_keeps_the_identity_an_mk3s_needs() {
    let mut unit = unit();
    unit = unit.act(10, &Action::Write(0x52, 2));
    unit = unit.act(10, &Action::Write(0x22, 500));
    unit = unit.act(10, &Action::Lanes([Lane::Parked, Lane::Loaded, Lane::Empty]));
    assert!(
        revision(&mut unit).starts_with("S2 A2*"),
        "{}",
        revision(&mut unit)
    );
    unit = unit.act(10, &Action::Forget);
    unit = unit.restart();
    assert!(
        revision(&mut unit).starts_with("S2 A2*"),
        "X42 kept 0x52: {}",
        revision(&mut unit)
    );
    let snapshot = unit.app.snapshot();
    assert_eq!(
        snapshot.settings.as_slice(),
        &[(0x52, 2)],
        "every other setting forgotten"
    );
    assert_eq!(snapshot.lanes, [Lane::Unknown; 3]);
}

/// A reset can come while a save is in progress (it runs a piece per step): `X0` finishes it and
/// saves everything, `X42` finishes it and forgets all but the identity.
#[test]
fn a_reset_during_a_save_in_progress_saves_or_forgets_everything() {
    for action in [BoardAction::Reset, BoardAction::EraseAndReset] {
        let mut unit = unit();
        unit = unit.act(10, &Action::Write(0x52, 2));
        unit = unit.act(10, &Action::Lanes([Lane::Parked, Lane::Loaded, Lane::Empty]));
        unit.ask(Request::write(0x22, 500));
        unit.believe(|s| {
            s.lanes = [Lane::Parked, Lane::Parked, Lane::Empty];
            s.counters.tool_changes[1] += 1;
        });
        // The full check that finds the new setting starts a save that runs in the next steps.
        unit.now = Instant::from_millis(unit.now.as_millis() + FULL_CHECK_MS);
        let _ = unit.keeper.update(&unit.app, unit.now);
        let _ = unit.keeper.update(&unit.app, unit.now + 1);
        assert!(unit.keeper.is_saving(), "{action:?}: a save in progress");
        let live = unit.app.snapshot();
        unit.keeper.before(action, &unit.app).unwrap();
        assert!(!unit.keeper.is_saving());
        let unit = unit.restart();
        let restored = unit.app.snapshot();
        match action {
            BoardAction::Reset => assert_eq!(restored, live, "X0 saves everything"),
            _ => {
                assert_eq!(
                    restored.settings.as_slice(),
                    &[(0x52, 2)],
                    "X42 keeps the identity"
                );
                assert_eq!(restored.lanes, [Lane::Unknown; 3]);
                assert_eq!(restored.counters, Default::default());
            }
        }
    }
}

#[test]
fn a_wiped_store_keeps_the_identity() {
    let mut unit = unit();
    unit = unit.act(10, &Action::Write(0x52, 2));
    unit = unit.act(10, &Action::Write(0x22, 500));
    // The wipe erases every page: more than the keeper's budget allows its store right after a
    // boot (`ERASES_AT_BOOT`), and not one of its saves, so the test allows them.
    unit.keeper.store().set_erase_allowance(u32::MAX);
    unit.keeper.store().wipe().unwrap();
    unit = unit.restart();
    assert!(
        revision(&mut unit).starts_with("S2 A2*"),
        "{}",
        revision(&mut unit)
    );
    assert_eq!(unit.app.snapshot().settings.as_slice(), &[(0x52, 2)]);
}

#[test]
fn an_unreadable_double_word_costs_its_entry_not_the_identity_nor_the_store() {
    let mut unit = unit();
    unit = unit.act(10, &Action::Write(0x52, 2));
    unit = unit.act(10, &Action::Lanes([Lane::Parked, Lane::Parked, Lane::Empty]));
    // The next lane save is cut at its second double word: it reads with an ECC error.
    unit.flash().cut_power_at(1, CutModel::Torn, 1);
    unit = unit.act(10, &Action::Lanes([Lane::InHub, Lane::Parked, Lane::Empty]));
    assert!(unit.flash().is_cut());
    unit.flash().power_on();
    assert!(
        unit.flash().has_ecc_errors(),
        "the torn program left an ECC error"
    );
    let mut unit = unit.restart();
    assert!(
        revision(&mut unit).starts_with("S2 A2*"),
        "{}",
        revision(&mut unit)
    );
    assert_eq!(
        unit.app.lanes(),
        [Lane::Parked, Lane::Parked, Lane::Empty],
        "the old lanes"
    );
    let news = unit.keeper.take_news().expect("the damage is reported");
    assert_eq!(news.repairs, 1);
    assert_eq!(unit.keeper.take_news(), None, "once");
    unit = unit.act(10, &Action::Lanes([Lane::Loaded, Lane::Parked, Lane::Empty]));
    let unit = unit.restart();
    assert_eq!(
        unit.app.lanes(),
        [Lane::Loaded, Lane::Parked, Lane::Empty],
        "saving goes on"
    );
}

/// A flash that stops programming and erasing: the keeper pauses between tries (1 s doubling to
/// 10 min), reports the trouble once, never erases more than its budget in any hour, and saves
/// again once the flash works.
#[test]
fn a_failing_flash_is_retried_with_pauses_and_a_bounded_erase_rate() {
    let mut unit = unit();
    // Fill every page, so that each page move has something to erase.
    for (wait, action) in mmu_sim::cut::life(3, 400) {
        unit = unit.act(wait, &action);
    }
    assert!(unit.flash().wear().erases >= 1);
    unit.keeper.take_news();
    unit.flash().set_broken(true);
    let start = unit.now.as_millis();
    let mut erases_at = Vec::new(); // the time of each erase attempt
    let mut news = Vec::new();
    let lanes = [
        [Lane::Parked, Lane::Empty, Lane::Empty],
        [Lane::InHub, Lane::Empty, Lane::Empty],
    ];
    // Three hours of steps (1 ms for the first 10 s, then 20 ms), the lanes changing every 100 ms.
    let steps = (0..10_000u64).chain((10_000..3 * 3_600_000).step_by(20));
    for step in steps {
        unit.now = Instant::from_millis(start + step);
        if step % 100 == 0 {
            unit.believe(|s| s.lanes = lanes[(step / 100 % 2) as usize]);
        }
        let before = unit.flash().wear().erases;
        let _ = unit.keeper.update(&unit.app, unit.now);
        for _ in before..unit.flash().wear().erases {
            erases_at.push(step);
        }
        news.extend(unit.keeper.take_news());
    }
    let worst_hour = erases_at
        .iter()
        .enumerate()
        .map(|(i, &at)| erases_at[i..].iter().take_while(|&&t| t < at + 3_600_000).count())
        .max()
        .unwrap_or(0);
    assert!(
        worst_hour <= (ERASE_BURST + ERASES_PER_HOUR) as usize,
        "{worst_hour} erases in one hour"
    );
    let first_second = erases_at.iter().filter(|&&t| t < 1000).count();
    assert!(first_second <= 2, "{first_second} erases in the first second");
    let health = unit.keeper.health();
    assert!(health.failing);
    assert!(
        (10..=40).contains(&health.failed_saves),
        "{} tries in 3 hours",
        health.failed_saves
    );
    assert_eq!(news.len(), 1, "reported once: {news:?}");
    // The flash works again: the next try saves, and says so once.
    unit.flash().set_broken(false);
    let later = start + 3 * 3_600_000 + 600_000;
    unit.now = Instant::from_millis(later);
    unit.save_steps();
    let recovered: Health = unit.keeper.take_news().expect("the recovery is reported");
    assert!(!recovered.failing);
    let lanes_now = unit.app.lanes();
    let unit = unit.restart();
    assert_eq!(unit.app.lanes(), lanes_now);
}
