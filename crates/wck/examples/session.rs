//! A realistic wCK session, encoded host side and decoded device side, without hardware.
//!
//! Run with `cargo run -p robobus-wck --example session`. For each command it prints the
//! packet bytes, what a module decodes from them, a reply a module could send and how the
//! host reads that reply, plus the modelled wire time at 115200 bit/s.
#![allow(clippy::print_stdout)]

use robobus_wck::program::Program;
use robobus_wck::timing::transaction_time;
use robobus_wck::{
    BaudRate, Command, DGain, Load, PGain, Position, Reply, ServoId, StreamDecoder, SyncMove,
    TorqueLevel,
};

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let servo = ServoId::new(3)?;
    let program = Program::parse(
        "# shuttle between 82 and 172, as in the manual's example (24)\n\
         move 82 torque 0\n\
         delay 266ms\n\
         move 172 torque 0\n\
         delay 266ms\n",
    )?;
    // (command, the reply a module could send)
    let session: Vec<(Command, Option<Reply>)> = vec![
        (
            Command::Move {
                id: servo,
                torque: TorqueLevel::new(0)?,
                position: Position::new(127)?,
            },
            Some(Reply::Status {
                load: Load::new(4)?,
                position: Position::new(96)?,
            }),
        ),
        (
            Command::StatusRead { id: servo },
            Some(Reply::Status {
                load: Load::new(9)?,
                position: Position::new(127)?,
            }),
        ),
        (
            Command::SyncMove(SyncMove::new(
                TorqueLevel::new(2)?,
                &[
                    Position::new(100)?,
                    Position::new(110)?,
                    Position::new(120)?,
                    Position::new(130)?,
                ],
            )?),
            None,
        ),
        (
            Command::GainRead { id: servo },
            Some(Reply::Gains {
                p: PGain::DEFAULT,
                d: DGain::DEFAULT,
            }),
        ),
        (
            Command::MotionWrite { id: servo, program },
            Some(Reply::MotionCount(program.count())),
        ),
    ];

    let baud = BaudRate::B115200;
    let mut device = StreamDecoder::new();
    for (command, reply) in &session {
        let packet = command.encode();
        println!("host   -> {command}");
        println!("  bytes   {packet}");
        for event in device.feed(&packet) {
            match event {
                Ok(heard) => println!("  device  {heard:?}"),
                Err(e) => println!("  device  error: {e}"),
            }
        }
        if let Command::MotionWrite { program, .. } = command {
            for (line, instruction) in program.instructions().iter().enumerate() {
                let (c, d) = instruction.to_pair();
                println!("          {line}: {c:02X} {d:02X}  {instruction}");
            }
        }
        match reply {
            Some(reply) => {
                let bytes = reply.to_bytes();
                println!("  reply   {}", hex(&bytes));
                match command.decode_reply(&bytes) {
                    Ok(decoded) => println!("  host    {decoded}"),
                    Err(e) => println!("  host    error: {e}"),
                }
            }
            None => println!("  reply   none"),
        }
        println!(
            "  time    {:.1} us at {baud} ({} + {} bytes)\n",
            transaction_time(command, baud).as_secs_f64() * 1e6,
            command.encoded_len(),
            command.reply_len(),
        );
    }

    // The manual's misprinted checksum of example (12): the device refuses it.
    let misprinted = [0xFF, 0xE0, 0x0B, 0x64, 0x64, 0x69];
    println!(
        "noise  -> {} (example (12) as printed in the manual)",
        hex(&misprinted)
    );
    for event in device.feed(&misprinted) {
        match event {
            Ok(heard) => println!("  device  {heard:?}"),
            Err(e) => println!("  device  error: {e}"),
        }
    }
    Ok(())
}
