//! The WHJ requests as command-line arguments (the `cli` feature): the value parsers their
//! `clap` attributes name. Each checks what the request's own check would (joint IDs
//! 1..=30, registers, the host bounds of [`crate::catalogue::bounds`]) so that a bad value
//! is refused while the arguments are parsed, with the value and its range; each gives the
//! request field's own type.

use robobus_whj::RegisterAddr;

use super::{parse_end_board_register, parse_register, parse_u32};
use crate::catalogue::args::Ids;
use crate::catalogue::bounds::{self, Bound};
use crate::ops::IdList;

/// A whole number, decimal or `0x` hex.
fn whole(s: &str) -> Result<u32, String> {
    parse_u32(s.trim()).ok_or_else(|| format!("`{s}` is not a whole number"))
}

/// One joint ID, 1..=30.
pub fn joint(s: &str) -> Result<u32, String> {
    let v = whole(s)?;
    robobus_whj::JointId::new(u8::try_from(v).unwrap_or(u8::MAX))
        .map(|j| u32::from(j.get()))
        .map_err(|_| robobus_whj::JointIdError { value: v }.to_string())
}

/// A list of joint IDs (`1`, `1-7`, `1,3,5-7`), sorted, without repeats.
pub fn joints(s: &str) -> Result<Ids, String> {
    let ids: IdList<robobus_whj::JointId> = s.parse()?;
    Ok(Ids::List(
        ids.sorted()
            .into_vec()
            .into_iter()
            .map(|j| u32::from(j.get()))
            .collect(),
    ))
}

/// A register by name or address, as its address (`0x14`).
pub fn register(s: &str) -> Result<String, String> {
    let (addr, _) = parse_register(s)?;
    Ok(hex(addr))
}

fn hex(addr: RegisterAddr) -> String {
    format!("{:#04X}", addr.get())
}

/// An end-board register by name or address 0x00..=0x7F, as its address.
pub fn end_board_register(s: &str) -> Result<String, String> {
    let addr = parse_end_board_register(s).map_err(|e| {
        if parse_u32(s.trim()).is_some() {
            return e;
        }
        let names: Vec<_> = robobus_whj::broadcast::END_BOARD_REGISTERS
            .iter()
            .map(|r| r.name)
            .collect();
        format!("{e} (names: {})", names.join(", "))
    })?;
    Ok(format!("{addr:#04X}"))
}

/// An end-board write, `REGISTER=VALUE` (the value 0..=65535), as `ADDRESS=VALUE`.
pub fn end_board_write(s: &str) -> Result<String, String> {
    let (reg, value) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}` is not REGISTER=VALUE (e.g. EB_IO1_MODE=1)"))?;
    let v = whole(value.trim())?;
    let value = u16::try_from(v).map_err(|_| format!("value {v} is out of range 0..=65535"))?;
    Ok(format!("{}={value}", end_board_register(reg)?))
}

/// A finite number.
pub fn finite(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("`{s}` is not a finite number"))
    }
}

/// A number within one of the host bounds (the message names the quantity and range).
fn bounded(s: &str, bound: &Bound) -> Result<f64, String> {
    let v = finite(s)?;
    bound.message(v).map_or(Ok(v), Err)
}

/// An angle, degrees.
pub fn angle(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::ANGLE_DEG)
}

/// A move's largest speed, degrees per second.
pub fn max_speed(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::MOVE_SPEED_DEG_S)
}

/// Frames per second.
pub fn frame_rate(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::FRAME_RATE_HZ)
}

/// A speed target, output RPM.
pub fn rpm(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::SPEED_RPM)
}

/// A current target, mA.
pub fn milliamps(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::CURRENT_MA)
}

/// How long a target is kept, seconds.
pub fn duration(s: &str) -> Result<f64, String> {
    bounded(s, &bounds::TARGET_DURATION_S)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joint_lists_sort_and_dedup() {
        assert_eq!(joints("3,1-2,2").unwrap(), Ids::List(vec![1, 2, 3]));
        assert!(joints("0").unwrap_err().contains("1..=30"));
        assert!(joints("5-2").is_err());
        assert!(joint("300").unwrap_err().contains("300"));
        assert_eq!(joint("0x1E").unwrap(), 30);
    }

    #[test]
    fn registers_by_name_or_address() {
        assert_eq!(register("cur_position").unwrap(), "0x14");
        assert_eq!(register("0x14").unwrap(), "0x14");
        assert_eq!(register("20").unwrap(), "0x14");
        assert!(register("0x92").unwrap_err().contains("0x92"));
        assert!(register("nope").is_err());
        assert_eq!(end_board_write("EB_IO1_MODE=1").unwrap(), "0x1D=1");
        assert_eq!(end_board_write("0x07=3").unwrap(), "0x07=3");
        assert!(
            end_board_write("0x80=1")
                .unwrap_err()
                .contains("0x00..=0x7F")
        );
    }
}
