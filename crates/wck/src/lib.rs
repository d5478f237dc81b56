//! RoboBuilder wCK servo protocol (work in progress: see issue 2).
#![cfg_attr(not(feature = "std"), no_std)]
