//! Golden tests: every number of the UART table in the wire-timing notes, the polling figures,
//! and the manual's section 2-3 response times.

#![allow(clippy::unwrap_used)] // test and bench set-up: a failed unwrap is a failed run

use core::time::Duration;

use robobus_wck::timing::{
    T_EEPROM, T_PROC, byte_time, operation_transaction_time, polling_rate_hz, response_time,
    sync_move_time, transaction_time, wire_polling_rate_hz, wire_time,
};
use robobus_wck::{BaudRate, Command, DGain, PGain, Position, ServoId, SyncMove, TorqueLevel};

fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

/// `value` printed with `decimals` decimals, as the table prints it.
fn printed(value: f64, decimals: usize) -> String {
    format!("{value:.decimals$}")
}

struct Row {
    baud: BaudRate,
    cmd_us: &'static str,
    reply_us: &'static str,
    txn_us: f64,
    txn_per_s: &'static str,
    sync_us: &'static str,
    sync_hz: &'static str,
}

const TABLE: [Row; 8] = [
    Row {
        baud: BaudRate::B4800,
        cmd_us: "8333.3",
        reply_us: "4166.7",
        txn_us: 13506.6,
        txn_per_s: "74",
        sync_us: "72916.7",
        sync_hz: "13.7",
    },
    Row {
        baud: BaudRate::B9600,
        cmd_us: "4166.7",
        reply_us: "2083.3",
        txn_us: 7256.6,
        txn_per_s: "138",
        sync_us: "36458.3",
        sync_hz: "27.4",
    },
    Row {
        baud: BaudRate::B38400,
        cmd_us: "1041.7",
        reply_us: "520.8",
        txn_us: 2569.1,
        txn_per_s: "389",
        sync_us: "9114.6",
        sync_hz: "109.7",
    },
    Row {
        baud: BaudRate::B57600,
        cmd_us: "694.4",
        reply_us: "347.2",
        txn_us: 2048.2,
        txn_per_s: "488",
        sync_us: "6076.4",
        sync_hz: "164.6",
    },
    Row {
        baud: BaudRate::B115200,
        cmd_us: "347.2",
        reply_us: "173.6",
        txn_us: 1527.4,
        txn_per_s: "655",
        sync_us: "3038.2",
        sync_hz: "329.1",
    },
    Row {
        baud: BaudRate::B230400,
        cmd_us: "173.6",
        reply_us: "86.8",
        txn_us: 1267.0,
        txn_per_s: "789",
        sync_us: "1519.1",
        sync_hz: "658.3",
    },
    Row {
        baud: BaudRate::B460800,
        cmd_us: "86.8",
        reply_us: "43.4",
        txn_us: 1136.8,
        txn_per_s: "880",
        sync_us: "759.5",
        sync_hz: "1316.6",
    },
    Row {
        baud: BaudRate::B921600,
        cmd_us: "43.4",
        reply_us: "21.7",
        txn_us: 1071.7,
        txn_per_s: "933",
        sync_us: "379.8",
        sync_hz: "2633.1",
    },
];

fn status_read() -> Command {
    Command::StatusRead {
        id: ServoId::new(1).unwrap(),
    }
}

fn sync_move_31() -> Command {
    Command::SyncMove(
        SyncMove::new(
            TorqueLevel::new(0).unwrap(),
            &[Position::new(100).unwrap(); 31],
        )
        .unwrap(),
    )
}

#[test]
fn uart_table_of_wire_timing_md() {
    for row in TABLE {
        let b = row.baud;
        assert_eq!(
            printed(us(wire_time(4, b)), 1),
            row.cmd_us,
            "{b}: 4 B command"
        );
        assert_eq!(
            printed(us(wire_time(2, b)), 1),
            row.reply_us,
            "{b}: 2 B reply"
        );
        // Modelled transaction = 60 / baud + T_PROC. The table's 2048.2 at 57600 is the sum
        // of its rounded columns (694.4 + 1006.6 + 347.2); the exact value is 2048.27, so
        // the comparison allows the table's last-digit rounding (0.1 µs).
        let txn = us(operation_transaction_time(b));
        assert!(
            (txn - row.txn_us).abs() < 0.1,
            "{b}: transaction {txn} vs {}",
            row.txn_us
        );
        assert_eq!(
            transaction_time(&status_read(), b),
            operation_transaction_time(b)
        );
        assert_eq!(
            printed(1e6 / txn, 0),
            row.txn_per_s,
            "{b}: transactions per second"
        );
        let sync = sync_move_time(31, b);
        assert_eq!(sync.as_nanos(), wire_time(35, b).as_nanos());
        assert_eq!(
            transaction_time(&sync_move_31(), b),
            sync,
            "{b}: sync move has no reply"
        );
        assert_eq!(printed(us(sync), 1), row.sync_us, "{b}: 35 B sync move");
        assert_eq!(
            printed(1.0 / sync.as_secs_f64(), 1),
            row.sync_hz,
            "{b}: sync rate"
        );
    }
}

#[test]
fn polling_figures() {
    // Polling 31 servos: 21.1 Hz at 115200 and 30.1 Hz at 921600 with the turnaround;
    // 61.9 Hz and 495.5 Hz on the wire alone.
    assert_eq!(printed(polling_rate_hz(31, BaudRate::B115200), 1), "21.1");
    assert_eq!(printed(polling_rate_hz(31, BaudRate::B921600), 1), "30.1");
    assert_eq!(
        printed(wire_polling_rate_hz(31, BaudRate::B115200), 1),
        "61.9"
    );
    assert_eq!(
        printed(wire_polling_rate_hz(31, BaudRate::B921600), 1),
        "495.5"
    );
    assert!(polling_rate_hz(0, BaudRate::B115200).abs() < f64::EPSILON);
}

#[test]
fn byte_time_is_ten_bit_times() {
    assert_eq!(byte_time(BaudRate::B9600), Duration::from_nanos(1_041_667));
    assert_eq!(byte_time(BaudRate::B921600), Duration::from_nanos(10_851));
    assert_eq!(T_PROC, Duration::from_nanos(1_006_600));
}

#[test]
fn manual_response_times_fit_the_model() {
    // Section 2-3: position move / read, passive, break, wheel: 1180 µs at 115200,
    // 1354 µs at 57600 (response = T_PROC + reply wire time).
    let op = status_read();
    assert!((us(response_time(&op, BaudRate::B115200)) - 1180.0).abs() < 1.0);
    assert!((us(response_time(&op, BaudRate::B57600)) - 1354.0).abs() < 1.0);
    // EEPROM sets: 121145 µs at 115200 and 121492 µs at 57600; the model uses 121 ms.
    let gain_set = Command::GainSet {
        id: ServoId::new(0).unwrap(),
        p: PGain::DEFAULT,
        d: DGain::DEFAULT,
    };
    assert_eq!(T_EEPROM, Duration::from_millis(121));
    assert!((us(response_time(&gain_set, BaudRate::B115200)) - 121_145.0).abs() < 200.0);
    assert!((us(response_time(&gain_set, BaudRate::B57600)) - 121_492.0).abs() < 200.0);
    assert_eq!(
        response_time(&sync_move_31(), BaudRate::B115200),
        Duration::ZERO
    );
}
