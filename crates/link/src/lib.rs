//! Links: byte links and CAN FD frame links (work in progress: see issue 4).
