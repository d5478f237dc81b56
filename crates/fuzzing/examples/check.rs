//! Runs one fuzz property on input files: `cargo run -p robobus-fuzzing --example check --
//! TARGET FILE...` (a crash libFuzzer kept, or a seed), printing each violation.

#![allow(clippy::print_stdout)]

fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((target, files)) = args.split_first() else {
        eprintln!("usage: check TARGET FILE...");
        return std::process::ExitCode::from(2);
    };
    let Some((_, check)) = robobus_fuzzing::TARGETS.iter().find(|(n, _)| n == target) else {
        eprintln!("check: no target {target}");
        return std::process::ExitCode::from(2);
    };
    let mut failed = false;
    for f in files {
        match std::fs::read(f) {
            Ok(data) => match check(&data) {
                Ok(()) => println!("{f}: ok"),
                Err(v) => {
                    println!("{f}: {v}");
                    failed = true;
                }
            },
            Err(e) => {
                eprintln!("{f}: {e}");
                failed = true;
            }
        }
    }
    if failed {
        std::process::ExitCode::FAILURE
    } else {
        std::process::ExitCode::SUCCESS
    }
}
