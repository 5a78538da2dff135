//! Feeds the whole unit logic ([`App`]) random byte streams and random sensor values, stepped
//! in virtual time. Besides "never panics", it checks what a user would notice first:
//! - never two slots fed towards the hub at once;
//! - no phase drives a motor beyond its bound (the slowest phase's bound with the default
//!   configuration);
//! - after any input, a `Q0` gets exactly one well-formed answer.
//!
//! `tests/properties.rs` is its bounded proptest twin that runs in CI.

#![no_main]

use libfuzzer_sys::fuzz_target;
use mmu_firmware::{HubSamples, Samples, SlotSamples};
use mmu_protocol::{Request, RequestCode};

#[path = "../../tests/common/bounds.rs"]
mod bounds;

use bounds::Bench;

const SLOTS: usize = 3;
/// Virtual time one input may run, ms (keeps each run short).
const MAX_RUN_MS: u64 = 60_000;

/// Takes values from the fuzzer's bytes; zeros once they run out.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> u8 {
        let (&first, rest) = self.0.split_first().unwrap_or((&0, &[]));
        self.0 = rest;
        first
    }

    fn adc(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()]) % 4096
    }

    fn samples(&mut self) -> Samples<SLOTS> {
        Samples {
            slots: core::array::from_fn(|_| SlotSamples {
                motor_hall: self.adc(),
                filament: self.adc(),
            }),
            hub: HubSamples {
                filament: self.adc(),
                tension: self.adc(),
                cutter: self.adc(),
            },
        }
    }

    /// What the printer sends: a valid frame, raw bytes, or nothing.
    fn rx(&mut self) -> Vec<u8> {
        match self.u8() % 4 {
            0 => {
                let code = RequestCode::ALL[usize::from(self.u8()) % RequestCode::ALL.len()];
                let value = self.u8() % 8;
                let request = if code == RequestCode::Write {
                    Request::write(value.wrapping_mul(9), u16::from_le_bytes([self.u8(), self.u8()]))
                } else {
                    Request::new(code, value)
                };
                request.encode().as_bytes().to_vec()
            }
            1 => (0..self.u8() % 24).map(|_| self.u8()).collect(),
            _ => Vec::new(),
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let mut bytes = Bytes(data);
    let mut bench = Bench::<SLOTS>::default();
    while !bytes.0.is_empty() && bench.now() < MAX_RUN_MS {
        let rx = bytes.rx();
        let samples = bytes.samples();
        let hold_ms = u64::from(bytes.u8()) * 4;
        if let Err(broken) = bench.feed(&rx, &samples, hold_ms) {
            panic!("{broken}");
        }
    }
});
