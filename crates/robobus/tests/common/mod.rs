//! Shared by the integration tests (`mod common;`): see each module.

#![allow(dead_code, unreachable_pub)]

pub mod reports;
