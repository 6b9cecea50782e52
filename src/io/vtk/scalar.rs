//! Numeric types of VTK data arrays, shared by the legacy and the XML reader.
//!
//! Input: a legacy type name (`float`, `vtktypeint64`, ...) or an XML `type` attribute, and the
//! raw bytes of one value. Output: the [`Scalar`], its size, and the value decoded in the byte
//! order the caller gives (legacy files are big-endian; XML files say which).

/// Numeric types of VTK data arrays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    Bit,
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    Str,
}

impl Scalar {
    /// A legacy type name (`float`, `unsigned_int`, `vtktypeint64`, ...), case-insensitive.
    pub(crate) fn legacy(name: &str) -> Option<Scalar> {
        use Scalar::*;
        Some(match name.to_ascii_lowercase().as_str() {
            "bit" => Bit,
            "char" | "signed_char" | "vtktypeint8" => I8,
            "unsigned_char" | "vtktypeuint8" => U8,
            "short" | "vtktypeint16" => I16,
            "unsigned_short" | "vtktypeuint16" => U16,
            "int" | "vtktypeint32" => I32,
            "unsigned_int" | "vtktypeuint32" => U32,
            "long" | "vtktypeint64" | "vtkidtype" | "long_long" | "__int64" => I64,
            "unsigned_long" | "vtktypeuint64" | "unsigned_long_long" | "unsigned___int64" => U64,
            "float" | "vtktypefloat32" => F32,
            "double" | "vtktypefloat64" => F64,
            "string" | "utf8_string" => Str,
            _ => return None,
        })
    }

    /// An XML `type` attribute (`Float32`, `Int64`, ...).
    pub(crate) fn xml(name: &str) -> Option<Scalar> {
        use Scalar::*;
        Some(match name {
            "Int8" | "Char" => I8,
            "UInt8" => U8,
            "Int16" => I16,
            "UInt16" => U16,
            "Int32" => I32,
            "UInt32" => U32,
            "Int64" | "IdType" => I64,
            "UInt64" => U64,
            "Float32" => F32,
            "Float64" => F64,
            "String" => Str,
            "Bit" => Bit,
            _ => return None,
        })
    }

    /// Bytes per value in binary data (0 for bits and strings, which are not fixed-size).
    pub(crate) fn size(self) -> usize {
        use Scalar::*;
        match self {
            Bit | Str => 0,
            I8 | U8 => 1,
            I16 | U16 => 2,
            I32 | U32 | F32 => 4,
            I64 | U64 | F64 => 8,
        }
    }

    pub(crate) fn is_int(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64 | Scalar::Str)
    }

    /// Decode one integer value; `b` holds at least [`Scalar::size`] bytes. Unsigned values
    /// beyond `i64::MAX` saturate (they are out of range as node indices or tags anyway).
    pub(crate) fn int_at(self, b: &[u8], big: bool) -> i64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        use Scalar::*;
        match self {
            I8 => get!(i8, 1) as i64,
            U8 | Bit => get!(u8, 1) as i64,
            I16 => get!(i16, 2) as i64,
            U16 => get!(u16, 2) as i64,
            I32 => get!(i32, 4) as i64,
            U32 => get!(u32, 4) as i64,
            I64 => get!(i64, 8),
            U64 => i64::try_from(get!(u64, 8)).unwrap_or(i64::MAX),
            F32 => get!(f32, 4) as i64,
            F64 => get!(f64, 8) as i64,
            Str => 0,
        }
    }

    /// Decode one value as a float; `b` holds at least [`Scalar::size`] bytes.
    pub(crate) fn float_at(self, b: &[u8], big: bool) -> f64 {
        match self {
            Scalar::F32 => {
                let mut a = [0u8; 4];
                a.copy_from_slice(&b[..4]);
                (if big {
                    f32::from_be_bytes(a)
                } else {
                    f32::from_le_bytes(a)
                }) as f64
            }
            Scalar::F64 => {
                let mut a = [0u8; 8];
                a.copy_from_slice(&b[..8]);
                if big {
                    f64::from_be_bytes(a)
                } else {
                    f64::from_le_bytes(a)
                }
            }
            _ => self.int_at(b, big) as f64,
        }
    }
}
