//! What `sequential-storage` 8.0.2 (the store this project used before) does on the STM32G0 when a
//! page erase is cut by a power loss: the erase leaves a mix of erased and old double words
//! (RM0444 §3.3; `mmu_sim::flash::CutModel::Torn`), while the crate's own mock flash only ever
//! erases a page from its start. The reproduction for the upstream report: one key written over
//! and over in a 4-page map until the map erases a page to reuse it; that erase is cut.

use embassy_futures::block_on;
use embedded_storage::nor_flash::{NorFlash as _, ReadNorFlash as _};
use mmu_sim::flash::{CutModel, FlashError, MemFlash};
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

/// The flash model (blocking, as the unit's store uses it) with the async traits the crate wants.
struct Flash(MemFlash<2048>);

impl Flash {
    fn new(pages: usize) -> Self {
        Flash(MemFlash::new(pages))
    }
}

impl embedded_storage_async::nor_flash::ErrorType for Flash {
    type Error = FlashError;
}

impl embedded_storage_async::nor_flash::ReadNorFlash for Flash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        self.0.read(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.0.capacity()
    }
}

impl embedded_storage_async::nor_flash::NorFlash for Flash {
    const WRITE_SIZE: usize = mmu_sim::flash::WRITE_SIZE;
    const ERASE_SIZE: usize = 2048;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        self.0.erase(from, to)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        self.0.write(offset, bytes)
    }
}
const REGION: core::ops::Range<u32> = 0..4 * 2048;

/// The value written the `n`th time.
fn value(n: u32) -> [u8; 64] {
    [n as u8; 64]
}

/// Write `n` values to key 1; `Err((k, error))` when the `k`th write failed.
fn write(
    map: &mut MapStorage<u8, Flash, Cache<Uncached, Uncached, Uncached, u8>>,
    n: u32,
) -> Result<(), (u32, String)> {
    let mut buffer = [0u8; 128];
    for k in 0..n {
        block_on(map.store_item(&mut buffer, &1u8, &&value(k)[..])).map_err(|e| (k, format!("{e:?}")))?;
    }
    Ok(())
}

fn map(flash: Flash) -> MapStorage<u8, Flash, Cache<Uncached, Uncached, Uncached, u8>> {
    MapStorage::new(flash, MapConfig::new(REGION), Cache::new_uncached())
}

/// Seeds of the torn erase whose outcome is wrong; the outcome of each seed is printed.
fn torn_erase_outcomes() -> Vec<String> {
    // The uncut run: how many writes until the first erase, and its operation.
    let mut uncut = map(Flash::new(4));
    let mut writes = 0;
    while uncut.flash().0.erase_operations.is_empty() {
        write(&mut uncut, 1).expect("uncut");
        writes += 1;
    }
    let erase = uncut.flash().0.erase_operations[0];
    let writes = writes + 40;
    let mut wrong = Vec::new();
    for seed in 0..32 {
        let mut flash = Flash::new(4);
        flash.0.cut_power_at(erase, CutModel::Torn, seed);
        let mut cut = map(flash);
        let (failed, _) = write(&mut cut, writes).expect_err("the cut");
        let mut flash = cut.destroy().0;
        flash.0.power_on();
        let mut rebooted = map(flash);
        let mut buffer = [0u8; 128];
        let fetched =
            block_on(rebooted.fetch_item::<&[u8]>(&mut buffer, &1u8)).map(|v| v.map(<[u8]>::to_vec));
        let old_or_new = |v: &[u8]| v == value(failed.saturating_sub(1)) || v == value(failed);
        let outcome = match &fetched {
            Ok(Some(v)) if old_or_new(v) => None,
            Ok(Some(v)) => Some(format!(
                "fetch gives write {} (the cut was during write {failed})",
                v[0]
            )),
            Ok(None) => Some("fetch finds nothing".to_string()),
            Err(e) => Some(format!("fetch fails: {e:?}")),
        };
        let errors: Vec<String> = (0..20)
            .filter_map(|_| write(&mut rebooted, 1).err().map(|(_, e)| e))
            .collect();
        let later = (!errors.is_empty()).then(|| {
            format!(
                "{} of 20 writes after the restart fail ({})",
                errors.len(),
                errors[0]
            )
        });
        let problems: Vec<String> = outcome.into_iter().chain(later).collect();
        if !problems.is_empty() {
            wrong.push(format!("seed {seed}: {}", problems.join("; ")));
        }
    }
    wrong
}

/// Documents the upstream behaviour: this test passes while the crate misbehaves, and fails
/// (asking for this file and the README's note to be updated) once it does not.
#[test]
fn a_torn_page_erase_brings_back_old_values_or_stops_the_map() {
    let wrong = torn_erase_outcomes();
    println!("{}", wrong.join("\n"));
    assert!(
        !wrong.is_empty(),
        "sequential-storage survives torn erases now: update the README note"
    );
}
