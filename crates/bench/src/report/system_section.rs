//! The report's system sections: the system calls per transaction and the transports'
//! own round trip.

use std::fmt::Write as _;

use crate::Results;

/// The system-call section: per transaction, the calling thread and the others.
pub fn syscalls_markdown(r: &Results) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "## System calls per transaction
"
    );
    if r.syscalls.is_empty() {
        let _ = writeln!(
            o,
            "Not counted in this run ({}). `robobus-bench syscalls [--udp]` counts them \
             with `strace`.\n",
            if r.smoke {
                "smoke mode"
            } else {
                "`strace` not found"
            }
        );
        return o;
    }
    let _ = writeln!(
        o,
        "Counted with `strace -ff -ttt` on the one-case runners in the sleep mode, between \
         two markers the measured loop leaves in the trace (the Python peers leave the same \
         markers); every thread of the traced process. Ours in the wCK case runs the \
         simulator's endpoint thread in the same process: it is the \"other threads\" column \
         there; a peer's simulator runs outside the trace, and ours over UDP talks to a \
         simulator process as the peer does.\n"
    );
    let _ = writeln!(
        o,
        "| case | transactions | caller per transaction | calls | other threads per transaction | calls |\n|---|---|---|---|---|---|"
    );
    for c in &r.syscalls {
        let t = c.transactions.max(1) as f64;
        let _ = writeln!(
            o,
            "| {} | {} | {:.1} | {} | {:.1} | {} |",
            c.what,
            c.transactions,
            c.caller.total as f64 / t,
            c.caller.per(c.transactions),
            c.others.total as f64 / t,
            c.others.per(c.transactions)
        );
    }
    let _ = writeln!(o);
    o
}

/// The transports' own round trip, both sides spinning.
pub(super) fn transport_section(o: &mut String, r: &Results) {
    let _ = writeln!(o, "## Transports\n");
    let Some((pty, memory)) = &r.echo else {
        let _ = writeln!(o, "Not measured.\n");
        return;
    };
    let _ = writeln!(
        o,
        "One byte through the pty and straight back, and one frame through the in-process \
         memory bus and straight back, both sides spinning (`robobus-bench echo`): what \
         each request/reply transaction over that transport costs at the least, whatever \
         the client and the simulator do. A pty hands every write to a kernel worker thread \
         before the other side can read it.\n"
    );
    let _ = writeln!(
        o,
        "| transport | round trips | p50 µs | p99 µs |\n|---|---|---|---|\n| pty | {} | {:.1} | {:.1} |\n| memory bus | {} | {:.1} | {:.1} |\n",
        pty.n, pty.p50, pty.p99, memory.n, memory.p50, memory.p99
    );
}
