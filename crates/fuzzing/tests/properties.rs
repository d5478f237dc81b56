//! The fuzz targets' properties in the ordinary test suite: every target holds on its seed
//! corpus and on random input, and each property catches the fault it is there for when
//! the checked code is broken on purpose.

#![allow(missing_docs, clippy::unwrap_used, clippy::panic)]

use std::path::Path;
use std::time::Duration;

use proptest::prelude::*;
use robobus_fuzzing::{PacketStream, TARGETS, Violation, alloc, position_inside};
use robobus_wck::{Command, DecodeError, StreamDecoder, checksum_range, decode_packet, xor7};
use robobus_whj::Reply;

fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/seeds")
        .join(target);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| std::fs::read(p).unwrap())
        .collect()
}

#[test]
fn every_target_has_a_seed_corpus_a_fuzz_binary_and_holds_on_it() {
    let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let manifest = std::fs::read_to_string(fuzz.join("Cargo.toml")).unwrap();
    for (name, check) in TARGETS {
        assert!(
            manifest.contains(&format!("name = \"{name}\"")),
            "fuzz/Cargo.toml has no target {name}"
        );
        assert!(
            fuzz.join("fuzz_targets")
                .join(format!("{name}.rs"))
                .exists(),
            "{name}"
        );
        let seeds = corpus(name);
        assert!(!seeds.is_empty(), "{name}: empty seed corpus");
        for seed in seeds {
            check(&seed).unwrap_or_else(|v| panic!("{name}: {v}"));
        }
    }
    // And every binary is a target of the list (a new parser gets both or neither).
    let binaries = manifest.matches("[[bin]]").count();
    assert_eq!(binaries, TARGETS.len());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn every_target_holds_on_random_input(data in proptest::collection::vec(any::<u8>(), 0..300)) {
        for (name, check) in TARGETS {
            prop_assert!(check(&data).is_ok(), "{}: {:?}", name, check(&data));
        }
    }
}

/// A stream decoder that skips its checksum check: a packet with a wrong checksum is
/// returned as the command its bytes would be with the right one.
struct NoChecksum {
    inner: StreamDecoder,
}

impl PacketStream for NoChecksum {
    fn push(&mut self, byte: u8) -> Option<Result<Command, DecodeError>> {
        match self.inner.push(byte)? {
            Err(DecodeError::BadChecksum { .. }) => {
                let mut raw = self.inner.last_packet().to_vec();
                let range = checksum_range(&raw);
                let last = raw.len() - 1;
                raw[last] = xor7(&raw[range]);
                Some(decode_packet(&raw))
            }
            other => Some(other),
        }
    }
    fn last_packet(&self) -> &[u8] {
        self.inner.last_packet()
    }
}

#[test]
fn a_stream_decoder_that_skips_its_checksum_is_caught() {
    // A status read of servo 1 with a wrong checksum (0x20 instead of 0x21).
    let data = [0xFF, 0xA1, 0x00, 0x20];
    assert!(robobus_fuzzing::wck_stream(&data).is_ok());
    let e = robobus_fuzzing::wck_stream_with(
        &mut NoChecksum {
            inner: StreamDecoder::new(),
        },
        &data,
    )
    .unwrap_err();
    assert!(e.0.contains("checksum"), "{e}");
}

#[test]
fn a_frame_decoder_that_drops_a_field_is_caught() {
    // A status reply of joint 1 (0x701), 16 bytes, temperature 25.0 °C (250).
    let mut data = vec![0x01, 0x07, 0x03];
    let mut status = [0u8; 16];
    status[4..6].copy_from_slice(&250i16.to_le_bytes());
    data.extend_from_slice(&status);
    assert!(robobus_fuzzing::whj_reply(&data).is_ok());
    let drop_temperature = |f: &robobus_whj::CanFrame| match Reply::from_frame(f).ok()? {
        Reply::Status { joint, mut status } => {
            status.temperature = robobus_whj::units::Temperature(0);
            Some(Reply::Status { joint, status })
        }
        other => Some(other),
    };
    let e = robobus_fuzzing::whj_reply_with(&data, drop_temperature, Reply::to_frame).unwrap_err();
    assert!(e.0.contains("encodes to"), "{e}");
}

#[test]
fn a_parser_position_outside_its_input_is_caught() {
    let text = "pose 0 10\nposes 1\n";
    assert!(position_inside(text, 1, 1));
    assert!(position_inside(text, 2, 8)); // one past the end of `poses 1`
    assert!(position_inside(text, 3, 1)); // the empty line after the last newline
    assert!(!position_inside(text, 2, 9));
    assert!(!position_inside(text, 4, 1));
    assert!(!position_inside(text, 0, 1));
    assert!(!position_inside(text, 1, 0));
    assert!(position_inside("", 1, 1));
    // A `\r` is a character: the end of a `\r\n` line is at column 2 or 3 of `a\r\n`.
    assert!(position_inside("a\r\nb", 1, 3));
    assert!(!position_inside("a\r\nb", 1, 4));
    // Columns count characters, not bytes.
    assert!(position_inside("é", 1, 2));
    assert!(!position_inside("é", 1, 3));
    // The parsers' real errors on broken input lie inside it (the targets hold).
    for bad in [
        "pose x",
        "torque 9\npose 0 1",
        "\n\n\u{1F600}",
        "pose 1 2 3\npose 0",
    ] {
        robobus_fuzzing::motion_text(bad.as_bytes()).unwrap();
        robobus_fuzzing::program_text(bad.as_bytes()).unwrap();
        robobus_fuzzing::robot_toml(bad.as_bytes()).unwrap();
    }
}

#[test]
fn an_allocation_beyond_the_bound_is_caught() {
    let input = [0u8; 100];
    // The fuzz binaries' allocator feeds the counters; here a check feeds them itself.
    let ok = alloc::check_bounded(&input, |_| {
        alloc::on_alloc(4096);
        alloc::on_dealloc(4096);
        Ok(())
    });
    assert_eq!(ok, Ok(()));
    let big = alloc::BASELINE + 100 * alloc::PER_INPUT_BYTE + 1;
    let e = alloc::check_bounded(&input, |_| {
        alloc::on_alloc(big);
        alloc::on_dealloc(big);
        Ok(())
    })
    .unwrap_err();
    assert!(e.0.contains("bytes allocated at once"), "{e}");
    // A violation of the check itself comes through.
    let v = alloc::check_bounded(&input, |_| Err(Violation("x".into())));
    assert_eq!(v, Err(Violation("x".into())));
}

#[test]
fn a_wck_client_without_its_quiet_guard_is_caught_crediting_shifted_replies() {
    // The script: 32 reads of servos 0..=31 % 31, then the device's fates. Fate 0x08: the
    // reply's first byte is duplicated on the wire (load, load, position).
    let mut data: Vec<u8> = (0..32).collect();
    data.extend(std::iter::repeat_n([0u8, 0x08], 64).flatten());
    assert_eq!(robobus_fuzzing::wck_matching(&data), Ok(()));
    let unguarded = robobus::wck::WckConfig {
        guard: Some(Duration::ZERO),
        ..robobus::wck::WckConfig::default()
    };
    let e = robobus_fuzzing::wck_matching_with(&data, unguarded).unwrap_err();
    assert!(e.0.contains("but it answered"), "{e}");
}

#[test]
fn a_whj_session_without_its_collision_window_is_caught_crediting_an_impostor() {
    // 32 reads, then the device's script: no foreign frames, the honest reply on time
    // with a second joint at the same ID answering 20 µs before it (fate 0x80).
    let mut data: Vec<u8> = (0..32).map(|i| i * 8).collect();
    data.extend(std::iter::repeat_n([0u8, 0x80], 64).flatten());
    assert_eq!(robobus_fuzzing::whj_matching(&data), Ok(()));
    let no_window = robobus::whj::JointBusConfig {
        collision_window: Some(Duration::ZERO),
        ..robobus::whj::JointBusConfig::default()
    };
    let e = robobus_fuzzing::whj_matching_with(&data, no_window).unwrap_err();
    assert!(e.0.contains("but it answered"), "{e}");
}
