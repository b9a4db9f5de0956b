//! The generated `quadrotor_rates` solver as a static library for C and C++ programs.
//!
//! The C ABI lives in `quadrotor_rates::ffi` (header:
//! `generated/quadrotor_rates/include/quadrotor_rates.h`); re-exporting it here keeps its
//! `#[no_mangle]` functions in `libc_abi_test.a`. This crate is `std`, so the archive
//! carries the panic handler and allocator shims a C program cannot supply.

pub use quadrotor_rates::ffi::*;
