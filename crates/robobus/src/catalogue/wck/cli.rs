//! The value parsers of the wCK requests' command-line arguments (the `cli` feature): text
//! to a request field's value, range-checked by the protocol crate's newtypes, so an
//! out-of-range value is refused by the argument parser naming the value and the range
//! (the parser names the argument) before anything is opened. Each returns the request's
//! plain field type; the library checks the request again when it plans or runs it.

use robobus_wck::{
    BaudRate, DataByte, ExtServoId, Position, Position10, RangeError, ServoId, TorqueLevel,
    WheelSpeed,
};

use crate::catalogue::args::Ids;
use crate::ops::IdList;

/// Parses a number: decimal or `0x` hex.
///
/// # Errors
/// The text, when it is not a whole number.
pub fn parse_u32(s: &str) -> Result<u32, String> {
    let t = s.trim();
    let parsed = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16),
        None => t.parse(),
    };
    parsed.map_err(|_| format!("`{s}` is not a whole number"))
}

/// Parses a byte-sized value with a protocol constructor; a negative value or one above
/// 255 gets the same message as the constructor's own range error.
///
/// # Errors
/// The constructor's range error, or the text when it is not a number.
pub fn ranged<T>(s: &str, new: impl Fn(u8) -> Result<T, RangeError>) -> Result<T, String> {
    // A negative number is out of range, not "not a number": name the range.
    if let Some(magnitude) = s.trim().strip_prefix('-')
        && parse_u32(magnitude).is_ok()
    {
        let (what, min, max) = (0..=u8::MAX)
            .find_map(|b| new(b).err())
            .or_else(|| new(u8::MAX).err())
            .map_or(("value", 0, 255), |e| (e.what, e.min, e.max));
        return Err(format!("{what} {} is out of range {min}..={max}", s.trim()));
    }
    let v = parse_u32(s)?;
    match u8::try_from(v) {
        Ok(b) => new(b).map_err(|e| e.to_string()),
        Err(_) => match new(u8::MAX) {
            Err(e) => Err(RangeError { value: v, ..e }.to_string()),
            Ok(_) => Err(format!("{v} is out of range 0..=255")),
        },
    }
}

/// A servo ID of the 4- and 6-byte commands, 0..=30.
///
/// # Errors
/// Out of range, or not a number.
pub fn servo_id(s: &str) -> Result<u32, String> {
    ranged(s, ServoId::new).map(|v| u32::from(v.get()))
}

/// A servo ID of the 10-bit commands, 0..=253.
///
/// # Errors
/// Out of range, or not a number.
pub fn ext_servo_id(s: &str) -> Result<u32, String> {
    ranged(s, ExtServoId::new).map(|v| u32::from(v.get()))
}

/// A position, 0..=254.
///
/// # Errors
/// Out of range, or not a number.
pub fn position(s: &str) -> Result<u32, String> {
    ranged(s, Position::new).map(|v| u32::from(v.get()))
}

/// A 10-bit position, 0..=1023.
///
/// # Errors
/// Out of range, or not a number.
pub fn position10(s: &str) -> Result<u32, String> {
    let v = parse_u32(s)?;
    let raw = u16::try_from(v).unwrap_or(u16::MAX);
    Position10::new(raw)
        .map(|p| u32::from(p.get()))
        .map_err(|e| RangeError { value: v, ..e }.to_string())
}

/// A torque level, 0..=4.
///
/// # Errors
/// Out of range, or not a number.
pub fn torque(s: &str) -> Result<u32, String> {
    ranged(s, TorqueLevel::new).map(|v| u32::from(v.get()))
}

/// A data byte, 0..=254 (the 10-bit move's torque).
///
/// # Errors
/// Out of range, or not a number.
pub fn data_byte(s: &str) -> Result<u32, String> {
    ranged(s, DataByte::new).map(|v| u32::from(v.get()))
}

/// A wheel speed, 0..=15.
///
/// # Errors
/// Out of range, or not a number.
pub fn wheel_speed(s: &str) -> Result<u32, String> {
    ranged(s, WheelSpeed::new).map(|v| u32::from(v.get()))
}

/// A baud rate the wCK supports, bit/s.
///
/// # Errors
/// A rate the wCK does not support (the error lists those it does), or not a number.
pub fn baud(s: &str) -> Result<u32, String> {
    let v = parse_u32(s)?;
    BaudRate::from_bits_per_second(v)
        .map(BaudRate::bits_per_second)
        .map_err(|e| e.to_string())
}

/// A list of servo IDs and ranges (`0-5,7`), each 0..=30, checked and kept as the list.
///
/// # Errors
/// An ID out of range, a backwards range or an empty item.
pub fn servo_ids(s: &str) -> Result<Ids, String> {
    let list: IdList<ServoId> = s.parse()?;
    Ok(Ids::List(
        list.as_slice().iter().map(|i| u32::from(i.get())).collect(),
    ))
}

/// A rate, Hz, 0.1..=200.
///
/// # Errors
/// Out of range, or not a number.
pub fn rate_hz(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if (0.1..=200.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("rate {v} Hz is out of range 0.1..=200"))
    }
}

/// A duration, seconds (a trailing `s` allowed), 0.1..=3600.
///
/// # Errors
/// Out of range, or not a number.
pub fn seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .trim_end_matches('s')
        .parse()
        .map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if (0.1..=3600.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} s is out of range 0.1..=3600"))
    }
}

/// A gain set `P,D` (`20,30`), P 1..=254, D 0..=254.
///
/// # Errors
/// Not `P,D`, or a gain out of range.
pub fn gains(s: &str) -> Result<[u32; 2], String> {
    crate::ops::wck::tune::parse_gains(s).map(|g| [u32::from(g.p.get()), u32::from(g.d.get())])
}

/// A byte, 0..=255 (the tuning step, which the library checks against its own range).
///
/// # Errors
/// Not a whole number, or one above 255.
pub fn small(s: &str) -> Result<u32, String> {
    s.parse::<u8>().map(u32::from).map_err(|e| e.to_string())
}
