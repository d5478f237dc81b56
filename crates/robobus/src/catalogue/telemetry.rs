//! The telemetry stream (placeholder module; see the stream below).
