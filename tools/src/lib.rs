//! brdfd's long-running studies, run as binaries of this package (`src/bin/`): the optimiser
//! reliability harness (`cargo run --release -p brdfd-tools --bin reliability`) and the
//! calibration of the bootstrap intervals (`--bin coverage`). They use only
//! brdfd's library, so their release build shares every compiled crate with the release binary.
//! What they share with each other and with brdfd's examples is in [`shared`].

pub mod shared;
