use super::*;

#[test]
fn manual_example_program_pairs() {
    // Section 3-11 example: move 100 at torque 1, delay 150, move 200 at torque 0, delay 250.
    let p = Program::parse(
        "move 100 torque 1\ndelay 150ms\nmove 200 torque 0  # comment\n\ndelay 250 ms\n",
    )
    .unwrap();
    let pairs: Vec<_> = p.pairs().collect();
    assert_eq!(pairs, [(0x11, 100), (0x30, 150), (0x10, 200), (0x30, 250)]);
}

#[test]
fn every_instruction_kind_round_trips_through_text_and_bytes() {
    let text = "none\nmove 82 torque 0\nmotion passive\nwheel cw 5\ndelay 266ms\nif adc >= 120\nif pos == 100\nrepeat forever\n";
    let p = Program::parse(text).unwrap();
    assert_eq!(p.to_string(), text);
    let mut bytes = [0u8; 16];
    for (i, (c, d)) in p.pairs().enumerate() {
        bytes[2 * i] = c;
        bytes[2 * i + 1] = d;
    }
    assert_eq!(Program::from_bytes(&bytes).unwrap(), p);
    let q = Program::parse(
        "motion break\nwheel ccw 15\noutput 2\nrepeat 3\nend\nif pos < 4\nif adc > 1\nif pos <= 9",
    )
    .unwrap();
    assert_eq!(q.to_string().parse::<Program>().unwrap(), q);
}

#[test]
fn parse_errors_point_at_line_and_column() {
    let e = Program::parse("move 82 torque 0\nif adc => 120\n").unwrap_err();
    assert_eq!((e.line, e.column), (2, 8));
    assert_eq!(
        e.to_string(),
        "line 2, column 8: expected a comparison operator (==, >, <, >=, <=), found `=>`"
    );
    let e = Program::parse("  move 300 torque 0").unwrap_err();
    assert_eq!((e.line, e.column), (1, 8));
    assert_eq!(
        e.to_string(),
        "line 1, column 8: position 300 is out of range 0..=254"
    );
    let e = Program::parse("move 3").unwrap_err();
    assert_eq!((e.line, e.column), (1, 7));
    assert_eq!(
        e.to_string(),
        "line 1, column 7: expected torque, found end of line"
    );
    let e = Program::parse("delay 255ms").unwrap_err();
    assert_eq!(
        e.kind,
        ParseErrorKind::Value(ValueError::DelayLowByteFf { ms: 255 })
    );
    let e = Program::parse("delay 5000ms").unwrap_err();
    assert!(
        e.to_string()
            .contains("delay (ms) 5000 is out of range 0..=4095"),
        "{e}"
    );
    let e = Program::parse("end extra").unwrap_err();
    assert_eq!((e.line, e.column), (1, 5));
    let e = Program::parse("jump 3").unwrap_err();
    assert!(
        e.to_string()
            .starts_with("line 1, column 1: expected an instruction"),
        "{e}"
    );
    let e = Program::parse("end\nend\nend\nend\nend\nend\nend\nend\nend").unwrap_err();
    assert_eq!((e.line, e.kind), (9, ParseErrorKind::TooManyInstructions));
    let e = Program::parse("repeat 0").unwrap_err();
    assert!(
        e.to_string()
            .contains("repeat count 0 is out of range 1..=254"),
        "{e}"
    );
    let e = Program::parse("wheel cw 99999999999").unwrap_err();
    assert!(e.to_string().contains("expected a decimal number"), "{e}");
    let e = Program::parse("motion verylongwordthatgoeson").unwrap_err();
    assert!(e.to_string().ends_with("found `verylongwordthat…`"), "{e}");
}

#[test]
fn instruction_decoding_rejects_unknown_fields() {
    assert_eq!(
        Instruction::from_pair(0x90, 0),
        Err(InstructionError::UnknownMain {
            command: 0x90,
            main: 9
        })
    );
    assert_eq!(
        Instruction::from_pair(0x15, 0),
        Err(InstructionError::UnknownSub { main: 1, sub: 5 })
    );
    assert_eq!(
        Instruction::from_pair(0x56, 0),
        Err(InstructionError::UnknownSub { main: 5, sub: 6 })
    );
    assert!(Instruction::from_pair(0x23, 16).is_err());
    assert_eq!(
        Instruction::from_pair(0x4F, 1).unwrap(),
        Instruction::Output(IoBits::new(1).unwrap())
    );
    assert_eq!(
        Instruction::from_pair(0x31, 0x0A).unwrap().to_string(),
        "delay 266ms"
    );
    assert_eq!(
        Program::from_bytes(&[0; 18]).unwrap_err().to_string(),
        "motion program bytes 18 is out of range 0..=16"
    );
}

#[test]
fn false_condition_semantics_is_skip_next() {
    assert_eq!(FALSE_CONDITION, FalseCondition::SkipNext);
    assert!(Compare::Ge.holds(120, 120));
    assert!(!Compare::Gt.holds(120, 120));
}
