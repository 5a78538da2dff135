//! Feeds arbitrary bytes to the printer's [`ResponseDecoder`]; the checks are in
//! `common/decoder.rs`.

#![no_main]

use libfuzzer_sys::fuzz_target;
use mmu_protocol::ResponseDecoder;

#[path = "common/decoder.rs"]
mod decoder;

fuzz_target!(|data: &[u8]| decoder::check::<ResponseDecoder>(data));
