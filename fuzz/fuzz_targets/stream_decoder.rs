//! Feeds arbitrary bytes to the wCK device-side stream decoder.
//!
//! Beyond "never panics", it checks what the decoder promises: every accepted packet starts
//! with the header, carries a correct checksum for its family, has the length of its
//! command, and re-encodes to a packet that decodes to the same command.
#![no_main]

use libfuzzer_sys::fuzz_target;
use robobus_wck::{DecodeError, StreamDecoder, checksum_range, decode_packet, xor7};

fuzz_target!(|data: &[u8]| {
    let mut decoder = StreamDecoder::new();
    for &byte in data {
        match decoder.push(byte) {
            Some(Ok(command)) => {
                let raw = decoder.last_packet();
                assert_eq!(raw.first(), Some(&0xFF));
                let (&checksum, _) = raw.split_last().expect("non-empty packet");
                assert_eq!(xor7(&raw[checksum_range(raw)]), checksum);
                assert_eq!(raw.len(), command.encoded_len());
                assert_eq!(decode_packet(&command.encode()), Ok(command));
            }
            Some(Err(DecodeError::BadChecksum { computed, received })) => {
                assert_ne!(computed, received);
            }
            Some(Err(_)) | None => {}
        }
    }
});
