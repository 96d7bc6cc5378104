//! splat-core's SPZ reader (`decode_spz`). SPZ versions 2 and 3 are one gzip stream, and random
//! changes to compressed bytes mostly fail gzip's checksum, so the first byte chooses: odd, the
//! rest is the file as it is (version 4's clear header and table included); even, the rest is a
//! gzip stream's content (header and attributes), compressed here first, so the fuzzer reaches
//! the header checks and the attribute decoding.
#![no_main]

use std::io::Write;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let path = std::path::Path::new("fuzz.spz");
    if mode & 1 == 1 {
        let _ = splat_core::spz::decode_spz(path, rest);
    } else {
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        gz.write_all(rest).unwrap();
        let _ = splat_core::spz::decode_spz(path, &gz.finish().unwrap());
    }
});
