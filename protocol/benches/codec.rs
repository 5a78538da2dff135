//! Decode + encode cost per message, reported (not asserted).

use criterion::{Criterion, black_box, criterion_group, criterion_main};
use mmu_protocol::{
    ErrorCode, ProgressCode, Request, RequestCode, RequestDecoder, Response, ResponseDecoder,
};

fn requests(c: &mut Criterion) {
    let frames: Vec<_> = [
        Request::new(RequestCode::Query, 0),
        Request::new(RequestCode::Tool, 2),
        Request::write(0x22, 360),
        Request::new(RequestCode::Read, 0x1b),
    ]
    .iter()
    .map(|r| r.encode())
    .collect();
    c.bench_function("request decode+encode", |b| {
        let mut decoder = RequestDecoder::new();
        b.iter(|| {
            for frame in &frames {
                for &byte in frame.as_bytes() {
                    if let Some(Ok(request)) = decoder.feed(black_box(byte)) {
                        black_box(request.encode());
                    }
                }
            }
        })
    });
}

fn responses(c: &mut Criterion) {
    let frames: Vec<_> = [
        Response::progress(RequestCode::Tool, 0, ProgressCode::FEEDING_TO_FSENSOR),
        Response::error(RequestCode::Tool, 0, ErrorCode::FSENSOR_DIDNT_SWITCH_ON),
        Response::read(&Request::new(RequestCode::Version, 3), 0x380),
        Response::accepted(&Request::new(RequestCode::Tool, 1)),
    ]
    .iter()
    .map(|r| r.encode())
    .collect();
    c.bench_function("response decode+encode", |b| {
        let mut decoder = ResponseDecoder::new();
        b.iter(|| {
            for frame in &frames {
                for &byte in frame.as_bytes() {
                    if let Some(Ok(response)) = decoder.feed(black_box(byte)) {
                        black_box(response.encode());
                    }
                }
            }
        })
    });
}

criterion_group!(benches, requests, responses);
criterion_main!(benches);
