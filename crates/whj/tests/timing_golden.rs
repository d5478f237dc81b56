//! Golden tests of the frame-time function: the wire-timing table of CAN FD frames.

// Test and bench code: a failed unwrap is a failed test.
#![allow(clippy::unwrap_used, clippy::panic)]
// Rates are small positive numbers rounded for comparison with the table.
#![allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]

use robobus_whj::CanFrame;
use robobus_whj::timing::{BitRates, fd_data_stuff_bounds, frame_bits, frame_duration};

fn fd(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::new_fd(CanFrame::standard_id(id).unwrap(), data).unwrap()
}

fn us(frame: &CanFrame) -> f64 {
    frame_bits(frame).micros(BitRates::WHJ)
}

/// Deterministic pseudo-random bytes (`SplitMix64`).
struct SplitMix(u64);
impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn fill(&mut self, buf: &mut [u8]) {
        for b in buf {
            *b = self.next().to_le_bytes()[0];
        }
    }
}

/// The table: (payload, best, typical, worst) in µs.
const TABLE: [(usize, f64, f64, f64); 5] = [
    (0, 35.8, 37.0, 38.8),
    (4, 42.0, 43.4, 46.6),
    (8, 48.4, 50.1, 54.6),
    (16, 61.2, 63.2, 70.6),
    (64, 139.0, 143.7, 167.6),
];
const DATA_BIT_US: f64 = 0.2;

/// Exact best and worst frame time over every 11-bit ID and every payload of `len` bytes.
fn best_worst(len: usize) -> (f64, f64) {
    let zeros = vec![0u8; len];
    let mut best = f64::MAX;
    let mut worst = 0.0f64;
    for id in 0..=0x7FFu16 {
        let f = fd(id, &zeros);
        let bits = frame_bits(&f);
        let (lo, hi) = fd_data_stuff_bounds(id, len, false).unwrap();
        let base = us(&f) - f64::from(bits.stuff_data) * DATA_BIT_US;
        best = best.min(base + f64::from(lo) * DATA_BIT_US);
        worst = worst.max(base + f64::from(hi) * DATA_BIT_US);
    }
    (best, worst)
}

/// Mean frame time over raw IDs 1..=30 with 200 pseudo-random payloads each.
fn typical(len: usize) -> f64 {
    let mut rng = SplitMix(42);
    let mut sum = 0.0;
    let mut data = vec![0u8; len];
    for id in 1..=30u16 {
        for _ in 0..200 {
            rng.fill(&mut data);
            sum += us(&fd(id, &data));
        }
    }
    sum / 6000.0
}

fn assert_near(what: &str, got: f64, want: f64) {
    assert!(
        (got - want).abs() <= 0.1 + 1e-9,
        "{what}: got {got:.3} µs, table {want} µs"
    );
}

#[test]
fn best_typical_worst_match_the_table() {
    for (len, best, typ, worst) in TABLE {
        let (b, w) = best_worst(len);
        assert_near(&format!("best {len} B"), b, best);
        assert_near(&format!("worst {len} B"), w, worst);
        assert_near(&format!("typical {len} B"), typical(len), typ);
    }
}

#[test]
fn stuff_bounds_match_the_documented_ranges() {
    // The table: s_dat is 1 for 0 bytes, 0..8 for 4 bytes, 0..32 for 16 bytes.
    assert_eq!(fd_data_stuff_bounds(0x201, 0, false), Some((1, 1)));
    assert_eq!(fd_data_stuff_bounds(0x201, 4, false), Some((0, 8)));
    assert_eq!(fd_data_stuff_bounds(0x501, 16, false), Some((0, 32)));
    assert_eq!(fd_data_stuff_bounds(0x501, 10, false), None);
    // s_arb: IDs 1..30 need 1 or 2 (as raw IDs in the 0x000 range).
    for id in 1..=30u16 {
        let s = frame_bits(&fd(id, &[])).stuff_arb;
        assert!((1..=2).contains(&s), "ID {id}: {s}");
    }
}

/// The DP bounds are reached by real payloads: search a first byte and a repeated byte.
#[test]
fn bounds_are_reached_by_concrete_payloads() {
    for len in [4usize, 8, 16] {
        let id = 0x201;
        let (lo, hi) = fd_data_stuff_bounds(id, len, false).unwrap();
        let mut seen_lo = u32::MAX;
        let mut seen_hi = 0;
        let mut data = vec![0u8; len];
        for first in 0..=255u8 {
            for rest in 0..=255u8 {
                data.fill(rest);
                data[0] = first;
                let s = frame_bits(&fd(id, &data)).stuff_data;
                seen_lo = seen_lo.min(s);
                seen_hi = seen_hi.max(s);
            }
        }
        assert_eq!((seen_lo, seen_hi), (lo, hi), "{len} B");
    }
}

#[test]
fn per_joint_cycle_figures() {
    let (b4, w4) = best_worst(4);
    let (b16, w16) = best_worst(16);
    let t4 = typical(4);
    let t16 = typical(16);
    assert_near("best cycle", b4 + b16, 103.2);
    assert_near("typical cycle", t4 + t16, 106.7);
    assert_near("worst cycle", w4 + w16, 117.2);
    let worst_cycle = w4 + w16;
    let typical_cycle = t4 + t16;
    // joints, worst cycle µs, max rate 100 %, 70 %, typical 100 %.
    let rows = [
        (1u32, 117.2, 8532, 5973, 9376),
        (7, 820.4, 1219, 853, 1339),
        (14, 1640.8, 609, 427, 670),
        (30, 3516.0, 284, 199, 313),
    ];
    for (n, cycle, full, seventy, typ) in rows {
        let c = f64::from(n) * worst_cycle;
        assert_near(&format!("{n} joints cycle"), c, cycle);
        assert_eq!((1e6 / c).round() as u32, full, "{n} joints at 100 %");
        assert_eq!((0.7e6 / c).round() as u32, seventy, "{n} joints at 70 %");
        let t = (1e6 / (f64::from(n) * typical_cycle)).round() as u32;
        assert!(t.abs_diff(typ) <= 1, "{n} joints typical: {t} vs {typ}");
    }
}

#[test]
fn without_brs_and_classic() {
    // Without BRS a 4-byte frame takes 94..105 µs.
    let (lo, hi) = fd_data_stuff_bounds(0x201, 4, false).unwrap();
    let mut min = f64::MAX;
    let mut max = 0.0f64;
    for id in 0..=0x7FFu16 {
        let f = fd(id, &[0; 4]).with_brs(false);
        let bits = frame_bits(&f);
        assert_eq!(bits.data_bits, 0);
        let base = us(&f) - f64::from(bits.stuff_data);
        min = min.min(base + f64::from(lo));
        max = max.max(base + f64::from(hi));
    }
    assert_near("no-BRS best", min, 94.0);
    assert_near("no-BRS worst", max, 105.0);
    // Classic 8-byte CAN 2.0A frame at 1 Mbit/s: 111..135 µs.
    let mut rng = SplitMix(7);
    let mut data = [0u8; 8];
    for id in [0u16, 0x7FF, 0x201, 0x555, 0x0AA] {
        for _ in 0..50 {
            rng.fill(&mut data);
            let f = CanFrame::new_classic(CanFrame::standard_id(id).unwrap(), &data).unwrap();
            let t = us(&f);
            assert!(
                (111.0..=135.0).contains(&t),
                "classic {id:#x} {data:?}: {t}"
            );
        }
    }
    let quiet = CanFrame::new_classic(CanFrame::standard_id(0x555).unwrap(), &[0x55; 8]).unwrap();
    assert!(us(&quiet) >= 111.0);
}

#[test]
fn duration_api_and_other_rates() {
    let f = fd(0x201, &[0x10, 0x27, 0, 0]);
    let d = frame_duration(&f, BitRates::WHJ);
    assert_eq!(d.as_nanos() % 200, 0, "multiples of the 200 ns data bit");
    // At 500k / 2M every nominal bit doubles and every data bit takes 500 ns.
    let bits = frame_bits(&f);
    let slow = bits.duration(BitRates::new(500_000, 2_000_000).unwrap());
    let expect = u128::from(bits.nominal_bits + 1) * 2000 + u128::from(bits.data_bits + 1) * 500;
    assert_eq!(slow.as_nanos(), expect);
    assert!(BitRates::new(0, 1).is_none());
}
