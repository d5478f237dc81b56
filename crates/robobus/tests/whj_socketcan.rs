//! The WHJ client on real `SocketCAN` (CAN FD on `vcan0`) inside User-Mode Linux: this
//! machine's kernel has no CAN support, so `scripts/uml/run-in-uml` (which provisions
//! itself) boots a guest with `vcan0` at MTU 72, and the inner test runs there: the
//! simulator serves seven joints on one `SocketCanLink`, the client talks to them through
//! another: the code path real hardware uses.

#![allow(clippy::unwrap_used)]
#![cfg(target_os = "linux")]

use crate::whj_common;

use std::time::Duration;

use robobus::whj::{CyclicConfig, JointBus, MotionLimits, Protocol, WhjError};
use robobus_link::SocketCanLink;
use robobus_whj::units::Position;
use robobus_whj::{JointId, WorkMode};
use whj_common::{Sim, chain};

const IN_UML_ENV: &str = "ROBOBUS_WHJ_IN_UML";

fn j(n: u8) -> JointId {
    JointId::new(n).unwrap()
}

fn deg(d: f64) -> Position {
    Position::from_degrees(d).unwrap()
}

#[test]
fn whj_client_on_socketcan_vcan0_inside_user_mode_linux() {
    let out = robobus_testkit::Inner::exact(module_path!(), "inner_socketcan_in_uml", IN_UML_ENV)
        .in_uml()
        .expect_marker("WHJ SOCKETCAN OK");
    eprintln!("{out}");
}

#[test]
#[ignore = "run by whj_client_on_socketcan_vcan0_inside_user_mode_linux inside User-Mode Linux"]
fn inner_socketcan_in_uml() {
    assert!(
        std::env::var_os(IN_UML_ENV).is_some(),
        "this test only runs inside the User-Mode Linux guest its outer test boots"
    );
    let sim = Sim::serve(chain(7), SocketCanLink::open("vcan0").unwrap());
    let bus =
        JointBus::open_with(SocketCanLink::open("vcan0").unwrap(), whj_common::config()).unwrap();
    let joints: Vec<_> = (1..=7).map(j).collect();
    for &id in &joints {
        let joint = bus.joint(id).unwrap();
        assert_eq!(joint.identity().unwrap().node_id, u16::from(id.get()));
        joint.disable().unwrap();
        joint.set_mode(WorkMode::Position).unwrap();
        joint.enable().unwrap();
    }
    let j1 = bus.joint_unchecked(j(1));
    j1.set_position_limits(deg(-100.0), deg(100.0)).unwrap();
    assert_eq!(j1.position_limits().unwrap(), (deg(-100.0), deg(100.0)));
    assert!(matches!(
        j1.save_to_flash(),
        Err(WhjError::SaveWhileEnabled { .. })
    ));
    let fb = j1.move_to(deg(20.0), MotionLimits::default()).unwrap();
    assert!((fb.position.degrees() - 20.0).abs() <= 0.1);

    for protocol in [Protocol::PointToPoint, Protocol::Broadcast] {
        let cyc = bus
            .cyclic(CyclicConfig {
                protocol,
                ..CyclicConfig::position(joints.clone(), Duration::from_millis(20))
            })
            .unwrap();
        cyc.set_positions(&(0..7).map(|i| deg(-f64::from(i))).collect::<Vec<_>>())
            .unwrap();
        std::thread::sleep(Duration::from_millis(1500));
        let stats = cyc.stop();
        eprintln!("SocketCAN {protocol:?} 7 joints every 20 ms: {stats:#?}");
        // User-Mode Linux runs on one emulated CPU: the numbers are a measurement; the
        // loop must run and the joints must arrive (checked below).
        assert!(stats.cycles >= 20, "{stats:?}");
        assert!(stats.complete >= 5, "{stats:?}");
        assert_eq!(
            stats.complete + stats.deadline_misses,
            stats.cycles,
            "{stats:?}"
        );
    }
    for (i, &id) in joints.iter().enumerate() {
        let p = bus.joint_unchecked(id).position().unwrap().degrees();
        let want = -f64::from(u8::try_from(i).unwrap());
        assert!((p - want).abs() < 0.1, "{id}: {p}° (want {want}°)");
    }
    drop(bus);
    drop(sim.stop());
    println!("WHJ SOCKETCAN OK");
}
