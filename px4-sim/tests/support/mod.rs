//! Shared by the loopback tests: a listening link on a free port. (Each test crate uses
//! some of it.)
#![allow(dead_code)]

use firmware_shim::transport::{Link, LinkOptions};

/// Opens `udpin:127.0.0.1:0` as the companion ([`LinkOptions::companion`]) and returns the
/// link with the free port the system gave it.
pub fn open_udpin_on_a_free_port() -> (Link, u16) {
    open_udpin_with(&LinkOptions::companion(1))
}

/// Opens `udpin:127.0.0.1:0` with `options` and returns the link with its port.
pub fn open_udpin_with(options: &LinkOptions) -> (Link, u16) {
    let link = Link::open_with(&"udpin:127.0.0.1:0".parse().unwrap(), options)
        .expect("a loopback UDP socket");
    let port = link
        .local_addr()
        .expect("a UDP link has a local address")
        .port();
    (link, port)
}
