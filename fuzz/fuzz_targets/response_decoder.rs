//! Feeds arbitrary bytes to the printer's [`ResponseDecoder`].
//!
//! Besides "never panics", it checks two invariants:
//! - every response the decoder accepts re-encodes to a frame that decodes to the same response;
//! - whatever came before, a newline followed by a valid frame decodes that frame.

#![no_main]

use libfuzzer_sys::fuzz_target;
use mmu_protocol::{DecodeError, MAX_FRAME_LEN, ParamCode, RequestCode, Response, ResponseDecoder};

fuzz_target!(|data: &[u8]| {
    let mut decoder = ResponseDecoder::new();
    for &byte in data {
        match decoder.feed(byte) {
            Some(Ok(response)) => check_round_trip(response),
            Some(Err(DecodeError::BadCrc {
                frame,
                computed,
                received,
            })) => {
                assert_ne!(computed, received);
                assert_eq!(frame.crc(), computed);
            }
            _ => {}
        }
    }

    // Resynchronisation: after a newline the decoder is ready for a fresh frame.
    let _ = decoder.feed(b'\n');
    let idle = Response::with_value(RequestCode::Reset, 0, ParamCode::Finished, 0);
    let frame = idle.encode();
    let results: Vec<_> = frame.as_bytes().iter().filter_map(|&b| decoder.feed(b)).collect();
    assert_eq!(results, [Ok(idle)]);
});

fn check_round_trip(response: Response) {
    let frame = response.encode();
    assert!(frame.as_bytes().len() <= MAX_FRAME_LEN);
    let mut fresh = ResponseDecoder::new();
    let results: Vec<_> = frame.as_bytes().iter().filter_map(|&b| fresh.feed(b)).collect();
    assert_eq!(results, [Ok(response)], "{frame:?}");
}
