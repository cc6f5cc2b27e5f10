//! MAVLink 2 signing keys: a 32-byte key file, or the SHA-256 of a passphrase
//! (the MAVProxy `signing setup PASSPHRASE` convention, also used by
//! Mission Planner and QGroundControl).

use sha2::{Digest, Sha256};
use std::path::Path;

/// The 32-byte secret key from the SHA-256 of `passphrase` (its UTF-8 bytes).
pub fn key_from_passphrase(passphrase: &str) -> [u8; 32] {
    let digest = Sha256::digest(passphrase.as_bytes());
    let mut key = [0u8; 32];
    key.copy_from_slice(&digest);
    key
}

/// Reads a key file holding exactly 32 raw bytes.
pub fn key_from_file(path: &Path) -> Result<[u8; 32], String> {
    let bytes =
        std::fs::read(path).map_err(|e| format!("signing key file {}: {e}", path.display()))?;
    <[u8; 32]>::try_from(bytes.as_slice()).map_err(|_| {
        format!(
            "signing key file {}: {} bytes, expected exactly 32",
            path.display(),
            bytes.len()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passphrase_key_is_its_sha256() {
        // SHA-256("abc"), FIPS 180-2 test vector.
        let expect = "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad";
        let hex = key_from_passphrase("abc")
            .iter()
            .fold(String::new(), |s, b| s + &format!("{b:02x}"));
        assert_eq!(hex, expect);
    }

    #[test]
    fn key_file_must_be_32_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let good = dir.path().join("good.key");
        std::fs::write(&good, [7u8; 32]).unwrap();
        assert_eq!(key_from_file(&good).unwrap(), [7u8; 32]);
        let short = dir.path().join("short.key");
        std::fs::write(&short, [7u8; 31]).unwrap();
        assert!(key_from_file(&short).unwrap_err().contains("31 bytes"));
        assert!(key_from_file(&dir.path().join("missing")).is_err());
    }
}
