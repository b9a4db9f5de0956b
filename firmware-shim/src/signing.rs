//! MAVLink 2 message signing (<https://mavlink.io/en/guide/message_signing.html>): the
//! 32-byte key, and the check of every received frame, with the `mavlink` crate's SHA-256
//! signature and its timestamp rules.
//!
//! A signed frame carries a 48-bit timestamp (10 us since 2015-01-01) and the first 6 bytes
//! of SHA-256(key, frame, link id, timestamp). A receiver takes a frame only if its
//! signature is right and its timestamp is newer than the last one of the same stream
//! (link id, system, component), or, for a new stream, at most a minute older than the
//! newest time it has seen: so a recorded frame played back is refused.

use std::path::{Path, PathBuf};

use mavlink::consts::v2::{IFLAG_SIGNED, SIGNATURE_VALUE_SIZE};
use mavlink::{MAVLinkV2MessageRaw, SigningConfig, SigningData};

/// Why a key file was refused.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// The file could not be read.
    #[error("signing key `{path}`: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The file holds neither 32 bytes nor 64 hexadecimal digits.
    #[error(
        "signing key `{path}`: {why}; give 32 bytes, or 64 hexadecimal digits (e.g. from \
         `head -c 32 /dev/urandom | xxd -p -c 64`)"
    )]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
}

/// A 32-byte MAVLink 2 signing key (its `Debug` does not show it).
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey([u8; 32]);

impl std::fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SigningKey(..)")
    }
}

impl SigningKey {
    /// The key `bytes`.
    pub fn new(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }

    /// Reads a key file: exactly 32 bytes, or 64 hexadecimal digits (surrounding white
    /// space allowed).
    ///
    /// # Errors
    /// [`KeyError::Read`], [`KeyError::Format`].
    pub fn load(path: &Path) -> Result<Self, KeyError> {
        let raw = std::fs::read(path).map_err(|source| KeyError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&raw).map_err(|why| KeyError::Format {
            path: path.to_path_buf(),
            why,
        })
    }

    /// The `mavlink` crate's configuration: sign as `link_id`, refuse unsigned frames.
    pub fn config(&self, link_id: u8) -> SigningConfig {
        SigningConfig::new(self.0, link_id, true, false)
    }

    fn parse(raw: &[u8]) -> Result<Self, String> {
        let text = std::str::from_utf8(raw).map(str::trim).unwrap_or("");
        if text.len() == 64 && text.bytes().all(|b| b.is_ascii_hexdigit()) {
            let mut key = [0u8; 32];
            for (k, pair) in key.iter_mut().zip(text.as_bytes().chunks(2)) {
                let digits = std::str::from_utf8(pair).map_err(|e| e.to_string())?;
                *k = u8::from_str_radix(digits, 16).map_err(|e| e.to_string())?;
            }
            return Ok(Self(key));
        }
        let key: [u8; 32] = raw
            .try_into()
            .map_err(|_| format!("{} bytes, not 32 (nor 64 hexadecimal digits)", raw.len()))?;
        Ok(Self(key))
    }
}

/// What the check made of a received frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Check {
    /// Signed with the key, newer than the stream's last frame: taken.
    Valid,
    /// Not signed.
    Unsigned,
    /// Signed, but not with this key (or altered).
    BadSignature,
    /// Signed with the key, but not newer than the stream's last frame: a replay.
    Replayed,
}

/// One link's signing: signs what it sends, checks what it receives.
pub struct Signer {
    key: SigningKey,
    data: SigningData,
}

impl std::fmt::Debug for Signer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Signer(..)")
    }
}

impl Signer {
    /// Signs as link `link_id`; unsigned frames are refused.
    pub fn new(key: SigningKey, link_id: u8) -> Self {
        let data = SigningData::from_config(key.config(link_id));
        Self { key, data }
    }

    /// The crate's signing state, for `mavlink::write_v2_msg_signed`.
    pub fn data(&self) -> &SigningData {
        &self.data
    }

    /// Checks `frame` (a CRC-valid MAVLink 2 frame) and, if [`Check::Valid`], advances its
    /// stream's timestamp.
    pub fn check(&self, frame: &MAVLinkV2MessageRaw) -> Check {
        if frame.incompatibility_flags() & IFLAG_SIGNED == 0 {
            return Check::Unsigned;
        }
        let mut expected = [0u8; SIGNATURE_VALUE_SIZE];
        frame.calculate_signature(&self.key.0, &mut expected);
        if expected != frame.signature_value() {
            return Check::BadSignature;
        }
        if self.data.verify_signature(frame) {
            Check::Valid
        } else {
            Check::Replayed
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_are_32_bytes_or_64_hex_digits() {
        let hex = "00112233445566778899aabbccddeeff00112233445566778899AABBCCDDEEFF\n";
        let k = SigningKey::parse(hex.as_bytes()).unwrap();
        assert_eq!(k.0[1], 0x11);
        assert_eq!(k.0[31], 0xff);
        assert_eq!(SigningKey::parse(&[7u8; 32]).unwrap().0, [7u8; 32]);
        assert!(
            SigningKey::parse(&[7u8; 31])
                .unwrap_err()
                .contains("31 bytes")
        );
        assert!(SigningKey::parse(&hex.as_bytes()[..63]).is_err());
        assert!(SigningKey::parse(&[b'g'; 64]).is_err());
        assert_eq!(format!("{k:?}"), "SigningKey(..)");
    }
}
