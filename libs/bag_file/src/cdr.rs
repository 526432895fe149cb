//! CDR payloads as rosbag2 stores them: the 4-byte encapsulation header (`00 01 00 00` for
//! little-endian plain CDR) followed by the message serialised as RustDDS serialises it.

use byteorder::{BigEndian, LittleEndian};
use serde::{Serialize, de::DeserializeOwned};

/// Encapsulation header of little-endian plain CDR, what we write.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Why a payload is not a CDR message of the expected type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    #[error("payload of {0} bytes is shorter than the 4-byte encapsulation header")]
    NoHeader(usize),
    #[error("encapsulation {0:02x} {1:02x} is not plain CDR (00 00 or 00 01)")]
    Encapsulation(u8, u8),
    #[error("{0}")]
    Body(String),
    #[error("{0} bytes are left over after the message (at most 3 bytes of padding are allowed)")]
    Trailing(usize),
    #[error("cannot serialise: {0}")]
    Serialise(String),
}

/// Serialises `message` as little-endian CDR with its encapsulation header.
pub fn encode<M: Serialize>(message: &M) -> Result<Vec<u8>, CdrError> {
    let mut out = CDR_LE_HEADER.to_vec();
    cdr_encoding::to_writer::<M, LittleEndian, _>(&mut out, message)
        .map_err(|e| CdrError::Serialise(e.to_string()))?;
    Ok(out)
}

/// Deserialises a CDR payload (either byte order) after checking its encapsulation header.
pub fn decode<M: DeserializeOwned>(payload: &[u8]) -> Result<M, CdrError> {
    let (header, body) = match payload.split_first_chunk::<4>() {
        Some((h, b)) => (h, b),
        None => return Err(CdrError::NoHeader(payload.len())),
    };
    let decoded = match (header[0], header[1]) {
        (0x00, 0x01) => cdr_encoding::from_bytes::<M, LittleEndian>(body),
        (0x00, 0x00) => cdr_encoding::from_bytes::<M, BigEndian>(body),
        (a, b) => return Err(CdrError::Encapsulation(a, b)),
    };
    let (message, used) = decoded.map_err(|e| CdrError::Body(e.to_string()))?;
    // DDS pads a sample to a multiple of 4 bytes; anything longer is not this type.
    let left = body.len().saturating_sub(used);
    if left > 3 {
        return Err(CdrError::Trailing(left));
    }
    Ok(message)
}

#[cfg(test)]
mod tests {
    use super::*;
    use qt_therapy_msgs::std_msgs::StringMsg;

    #[test]
    fn round_trip_and_header() {
        let m = StringMsg {
            data: "QT/happy".into(),
        };
        let bytes = encode(&m).expect("encodes");
        assert_eq!(&bytes[..4], &CDR_LE_HEADER);
        // u32 length 9 (with the NUL), then the text and its NUL.
        assert_eq!(&bytes[4..8], &9u32.to_le_bytes());
        assert_eq!(decode::<StringMsg>(&bytes), Ok(m));
    }

    #[test]
    fn rejects_bad_payloads() {
        assert_eq!(decode::<StringMsg>(&[0, 1]), Err(CdrError::NoHeader(2)));
        assert_eq!(
            decode::<StringMsg>(&[0, 3, 0, 0, 0, 0, 0, 0]),
            Err(CdrError::Encapsulation(0, 3))
        );
        assert!(matches!(
            decode::<StringMsg>(&[0, 1, 0, 0, 200, 0, 0, 0, b'a']),
            Err(CdrError::Body(_))
        ));
        let mut long = encode(&StringMsg { data: "a".into() }).expect("encodes");
        long.extend_from_slice(&[0; 8]);
        assert!(matches!(
            decode::<StringMsg>(&long),
            Err(CdrError::Trailing(_))
        ));
    }
}
