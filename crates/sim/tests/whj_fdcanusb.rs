//! The host's fdcanusb link against the emulated fdcanusb with simulated joints behind it,
//! in process on the virtual clock.

#![allow(clippy::unwrap_used)] // test code

use core::time::Duration;

use robobus_link::fdcanusb::codec;
use robobus_link::{AdapterErrorKind, ByteLink, FdcanusbConfig, FdcanusbLink, FrameLink};
use robobus_sim::whj::adapter::{AdapterSimLink, FdcanusbAdapter, SerialTime};
use robobus_sim::whj::{WhjBus, WhjModel, WhjSimLink};
use robobus_whj::CanFrame;
use robobus_whj::timing::BitRates;

fn iap_release() -> CanFrame {
    CanFrame::new_fd(CanFrame::standard_id(0x001).unwrap(), &[0x02, 0x49, 0x00]).unwrap()
}

fn no_polls() -> FdcanusbConfig {
    FdcanusbConfig {
        status_every: Duration::from_secs(3600),
        ..FdcanusbConfig::default()
    }
}

#[test]
fn a_reply_through_the_fdcanusb_costs_the_wire_plus_both_lines_serial_time_exactly() {
    let mut reference = WhjBus::chain([1], WhjModel::Whj30, 7);
    let wire = reference.request(iap_release())[0].at;

    let (bus, handle) = WhjSimLink::new(WhjBus::chain([1], WhjModel::Whj30, 7));
    // The adapter powers up at other rates: opening sets the joints'.
    let adapter = FdcanusbAdapter::new(
        BitRates::new(500_000, 2_000_000).unwrap(),
        SerialTime::default(),
    );
    let port = AdapterSimLink::new(Box::new(adapter), bus);
    let epoch = port.now();
    let mut link = FdcanusbLink::open(port, "sim", no_polls()).unwrap();
    assert_eq!(handle.with_bus(|b| b.rates()), BitRates::WHJ);
    assert_eq!(handle.with_bus(|b| b.stats().host_frames), 0);
    let t0 = link.now();
    link.send(&iap_release()).unwrap();
    // "can std 1 024900 BF\n" in, then "OK\r\n" out.
    let line_in = SerialTime::USB_CDC.of(20);
    assert_eq!(link.now() - t0, line_in + SerialTime::USB_CDC.of(4));
    let rx = link.recv(t0 + Duration::from_millis(5)).unwrap();
    assert_eq!(rx.frame.raw_id(), 0x101);
    assert_eq!(rx.frame.data(), &[0x02, 0x49, 0x01]);
    // The adapter heard the reply at the wire's instant; its line carries that time.
    let heard = t0 + line_in + wire;
    let micros = u32::try_from((heard - epoch).as_micros()).unwrap();
    let rcv = codec::encode_rcv(&rx.frame, Some(micros), Some(-1));
    assert_eq!(link.now(), heard + SerialTime::USB_CDC.of(rcv.len()));
    // Nothing else: the receive ends exactly at its deadline.
    let deadline = link.now() + Duration::from_millis(3);
    assert!(link.recv(deadline).unwrap_err().is_timeout());
    assert_eq!(link.now(), deadline);
    assert_eq!(handle.with_bus(|b| b.stats().host_frames), 1);
}

#[test]
fn an_fdcanusb_that_cannot_make_5_mbit_is_refused_before_a_frame_reaches_the_joints() {
    let (bus, handle) = WhjSimLink::new(WhjBus::chain([1], WhjModel::Whj30, 7));
    let adapter = FdcanusbAdapter::default().with_max_rates(1_000_000, 2_000_000);
    let port = AdapterSimLink::new(Box::new(adapter), bus);
    let e = FdcanusbLink::open(port, "/dev/ttyACM0", no_polls()).unwrap_err();
    assert_eq!(e.kind, AdapterErrorKind::RateUnsupported);
    assert_eq!(
        e.to_string(),
        "fdcanusb adapter on /dev/ttyACM0: cannot set can.fd_bitrate to 5000000: it answered \
         ERR can.fd_bitrate 5000000 cannot be set (allowed: 125000..=2000000 bit/s) (the \
         joints need can.fd_bitrate 5000000; an fdcanusb takes 125000..=8000000 bit/s); \
         nothing was sent to a joint"
    );
    assert_eq!(handle.with_bus(|b| b.stats().host_frames), 0);
}
