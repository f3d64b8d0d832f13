//! Model files (`models/*.mrsm`): whatever the bytes, `model::decode` returns a model or
//! a typed error, never panics; a model it accepts gives a tracking extent or an error.
//!
//! A random mutation almost never keeps the CRC-32 right, which would stop every input
//! at the checksum. So each input is decoded twice: as it is, and with its checksum
//! recomputed (where its length fields leave room for one), which lets the fuzzer reach
//! the header and payload decoders and the map's consistency checks.

#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

/// CRC-32 (IEEE, reflected), bit by bit: independent of the crate's table version.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
        }
    }
    !c
}

/// Where the checksum of `bytes` sits if its length fields are believed.
fn checksum_offset(bytes: &[u8]) -> Option<usize> {
    let h = u32::from_le_bytes(bytes.get(10..14)?.try_into().ok()?) as usize;
    let header_end = 14usize.checked_add(h)?;
    let p = u64::from_le_bytes(bytes.get(header_end..header_end.checked_add(8)?)?.try_into().ok()?);
    let end = (header_end + 8).checked_add(usize::try_from(p).ok()?)?;
    (end.checked_add(4)? <= bytes.len()).then_some(end)
}

fn exercise(bytes: &[u8]) {
    let origin = Path::new("fuzz.mrsm");
    let _ = mrsmap::model::decode_header(bytes, origin);
    if let Ok(model) = mrsmap::model::decode(bytes, origin) {
        let _ = model.extent();
        let _ = model.world_from_model();
    }
}

fuzz_target!(|data: &[u8]| {
    exercise(data);
    if let Some(end) = checksum_offset(data) {
        let mut fixed = data.to_vec();
        let crc = crc32(&fixed[..end]);
        fixed[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        exercise(&fixed);
    }
});
