//! Fuzz target: the `.mpc` parser and its diagnostics renderer must never panic.
//!
//! Run from the repository root, seeded with the model files:
//! `cargo +nightly fuzz run parse_mpc fuzz/corpus/parse_mpc models -- -max_total_time=300`
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let src = String::from_utf8_lossy(data);
    if let Err(d) = mpc_dsl::lang::check_source(&src) {
        let _ = d.render("fuzz.mpc", &src);
    }
});
