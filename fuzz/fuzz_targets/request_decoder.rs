//! Feeds arbitrary bytes to the unit's [`RequestDecoder`].
//!
//! Besides "never panics", it checks two invariants:
//! - every request the decoder accepts re-encodes to a frame that decodes to the same request;
//! - whatever came before, a newline followed by a valid frame decodes that frame.

#![no_main]

use libfuzzer_sys::fuzz_target;
use mmu_protocol::{DecodeError, MAX_FRAME_LEN, Request, RequestCode, RequestDecoder};

fuzz_target!(|data: &[u8]| {
    let mut decoder = RequestDecoder::new();
    for &byte in data {
        match decoder.feed(byte) {
            Some(Ok(request)) => check_round_trip(request),
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
    let query = Request::new(RequestCode::Query, 0);
    let frame = query.encode();
    let results: Vec<_> = frame.as_bytes().iter().filter_map(|&b| decoder.feed(b)).collect();
    assert_eq!(results, [Ok(query)]);
});

fn check_round_trip(request: Request) {
    let frame = request.encode();
    assert!(frame.as_bytes().len() <= MAX_FRAME_LEN);
    let mut fresh = RequestDecoder::new();
    let results: Vec<_> = frame.as_bytes().iter().filter_map(|&b| fresh.feed(b)).collect();
    assert_eq!(results, [Ok(request)], "{frame:?}");
}
