//! Reader stub.

use super::raw::{Location, ParseError, RawMesh};

pub fn read(_data: &[u8]) -> Result<RawMesh, ParseError> {
    Err(ParseError::new(
        Location::File,
        "reader not implemented yet",
    ))
}
