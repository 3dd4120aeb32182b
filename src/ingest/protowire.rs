//! The protobuf wire format, only as far as the `tirewear.v1` messages use
//! it: the fast path of telemetry decoding (packed float arrays read straight
//! from the decompressed chunk, per-sample fields without a message struct).
//!
//! Anything else a valid encoder may write (unknown fields, an unpacked or
//! split repeated field, a field with another wire type) makes these readers
//! give up (`None`); the caller then decodes the message with `prost`, which
//! accepts every valid encoding and names what is wrong with an invalid one.
//! Both routes give the same series: `tests/oracle_mcap.rs` and the unit
//! tests below compare them.

/// One field's value as it appears on the wire.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Field<'a> {
    /// Wire type 0.
    Varint(u64),
    /// Wire type 1 (little-endian).
    Fixed64([u8; 8]),
    /// Wire type 2.
    Bytes(&'a [u8]),
    /// Wire type 5 (little-endian).
    Fixed32([u8; 4]),
}

/// A base-128 varint at the front of `buf`, which is advanced past it.
/// `None` when it runs off the end or is longer than a u64 allows.
/// One and two bytes (tags, and a packed array's length up to 16 KiB:
/// all but a block's start time and period) are read inline where it is
/// called; longer ones take a call ([`varint_long`]).
#[inline(always)]
pub(crate) fn varint(buf: &mut &[u8]) -> Option<u64> {
    match **buf {
        [b0, ..] if b0 < 0x80 => {
            *buf = &buf[1..];
            Some(u64::from(b0))
        }
        [b0, b1, ..] if b1 < 0x80 => {
            *buf = &buf[2..];
            Some(u64::from(b0 & 0x7f) | u64::from(b1) << 7)
        }
        _ => varint_long(buf),
    }
}

/// [`varint`] of three bytes or more (or none), byte by byte.
#[inline(never)]
fn varint_long(buf: &mut &[u8]) -> Option<u64> {
    let mut value = 0u64;
    for i in 0..10 {
        let byte = *buf.get(i)?;
        // The tenth byte holds bit 63 only.
        if i == 9 && byte > 1 {
            return None;
        }
        value |= u64::from(byte & 0x7f) << (7 * i);
        if byte < 0x80 {
            *buf = &buf[i + 1..];
            return Some(value);
        }
    }
    None
}

/// The field at the front of `buf` (its number and value); `buf` is advanced
/// past it. `None` for a malformed field or a group (wire types 3 and 4).
/// Always inlined: called once per field of every block, in the loop that
/// matches the field's number.
#[inline(always)]
pub(crate) fn next_field<'a>(buf: &mut &'a [u8]) -> Option<(u32, Field<'a>)> {
    let key = varint(buf)?;
    let number = u32::try_from(key >> 3).ok().filter(|&n| n > 0)?;
    let field = match key & 7 {
        0 => Field::Varint(varint(buf)?),
        1 => {
            let (head, rest) = buf.split_first_chunk::<8>()?;
            *buf = rest;
            Field::Fixed64(*head)
        }
        2 => {
            let len = usize::try_from(varint(buf)?).ok()?;
            let bytes = buf.get(..len)?;
            *buf = &buf[len..];
            Field::Bytes(bytes)
        }
        5 => {
            let (head, rest) = buf.split_first_chunk::<4>()?;
            *buf = rest;
            Field::Fixed32(*head)
        }
        _ => return None,
    };
    Some((number, field))
}

/// A channel's element type: `float` (fixed32) or `double` (fixed64).
pub(crate) trait Scalar: Copy + Default {
    /// Bytes per element in a packed array.
    const SIZE: usize;
    /// The wire type of a singular field (5: fixed32, 1: fixed64).
    const WIRE: u32;
    /// A singular field's value at the front of `buf` (after its key), and
    /// the rest; `None` if `buf` is too short.
    fn read_fixed(buf: &[u8]) -> Option<(Self, &[u8])>;
    /// Appends a packed array's elements (`bytes.len()` a multiple of `SIZE`).
    fn extend_packed(v: &mut Vec<Self>, bytes: &[u8]);
}

/// `Scalar` for a float type: its size and protobuf wire type (fixed32 = 5,
/// fixed64 = 1), little-endian on the wire.
macro_rules! scalar {
    ($t:ty, $size:literal, $wire:literal) => {
        impl Scalar for $t {
            const SIZE: usize = $size;
            const WIRE: u32 = $wire;
            #[inline]
            fn read_fixed(buf: &[u8]) -> Option<(Self, &[u8])> {
                let (head, rest) = buf.split_first_chunk::<$size>()?;
                Some((<$t>::from_le_bytes(*head), rest))
            }
            fn extend_packed(v: &mut Vec<Self>, bytes: &[u8]) {
                #[cfg(target_endian = "little")]
                copy_le(v, bytes);
                #[cfg(not(target_endian = "little"))]
                extend_le(v, bytes, <$t>::from_le_bytes);
            }
        }
    };
}
scalar!(f32, 4, 5);
scalar!(f64, 8, 1);

/// Appends little-endian elements on a little-endian machine: one
/// reservation and one `memcpy` of the bytes. The element loop of
/// [`extend_le`] compiles to the same copy in most builds, but not in all
/// (one build left it a loop, 10 % of a decode profile: docs/performance.md),
/// and the packed arrays are most of the bytes decoded.
#[cfg(target_endian = "little")]
fn copy_le<T: bytemuck::Pod>(v: &mut Vec<T>, bytes: &[u8]) {
    let n = bytes.len() / size_of::<T>();
    debug_assert_eq!(
        n * size_of::<T>(),
        bytes.len(),
        "packed length checked by the caller"
    );
    v.reserve(n);
    let old = v.len();
    // SAFETY: the reservation leaves room for `n` more elements after
    // `old`; the source holds `n · size_of::<T>()` bytes and cannot overlap
    // the vector's buffer (a shared borrow beside a unique one); `T: Pod`
    // makes every bit pattern a valid element, in the machine's (little)
    // byte order, which is the wire's. Byte copies need no alignment.
    unsafe {
        std::ptr::copy_nonoverlapping(
            bytes.as_ptr(),
            v.as_mut_ptr().add(old).cast::<u8>(),
            n * size_of::<T>(),
        );
        v.set_len(old + n);
    }
}

/// Appends little-endian elements one by one (big-endian machines).
#[cfg_attr(target_endian = "little", allow(dead_code))]
fn extend_le<T: Copy, const N: usize>(v: &mut Vec<T>, bytes: &[u8], from: fn([u8; N]) -> T) {
    let (elements, rest) = bytes.as_chunks::<N>();
    debug_assert!(rest.is_empty(), "packed length checked by the caller");
    v.extend(elements.iter().map(|b| from(*b)));
}

/// A packed array's length in elements, if `bytes` holds whole elements.
pub(crate) fn packed_len<T: Scalar>(bytes: Option<&[u8]>) -> Option<usize> {
    let len = bytes.map_or(0, <[u8]>::len);
    len.is_multiple_of(T::SIZE).then_some(len / T::SIZE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varints_read_as_the_protobuf_encoding_guide_writes_them() {
        // https://protobuf.dev/programming-guides/encoding/: 150 = 96 01.
        let mut b: &[u8] = &[0x96, 0x01, 0x07];
        assert_eq!(varint(&mut b), Some(150));
        assert_eq!(b, &[0x07]);
        let mut max: &[u8] = &[0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01];
        assert_eq!(varint(&mut max), Some(u64::MAX));
        // Eleven bytes, a tenth byte above 1, and a varint cut short.
        let mut long: &[u8] = &[0xff; 11];
        assert_eq!(varint(&mut long), None);
        let mut over: &[u8] = &[0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x02];
        assert_eq!(varint(&mut over), None);
        let mut cut: &[u8] = &[0x80];
        assert_eq!(varint(&mut cut), None);
    }

    #[test]
    fn varints_of_every_length_read_as_prost_writes_them() {
        // Both sides of each length's boundary (1, 2 and 3 bytes are
        // read by different code), then every tenth-power and u64::MAX.
        let mut values: Vec<u64> = (0..10)
            .flat_map(|k| {
                let edge = 1u64 << (7 * k);
                [edge.saturating_sub(1), edge, edge + 1]
            })
            .collect();
        values.extend((0..20).map(|k| 10u64.pow(k)));
        values.push(u64::MAX);
        for v in values {
            let mut bytes = Vec::new();
            prost::encoding::encode_varint(v, &mut bytes);
            bytes.push(0x2a);
            let mut b = bytes.as_slice();
            assert_eq!(varint(&mut b), Some(v), "{v}");
            assert_eq!(b, &[0x2a], "{v}: what is left");
            // Cut one byte short, it is no varint.
            let mut cut = &bytes[..bytes.len() - 2];
            assert_eq!(varint(&mut cut), None, "{v} cut short");
        }
    }

    #[test]
    fn fields_of_each_wire_type_and_malformed_ones() {
        // Field 1 varint 3; field 2 fixed32 1.0; field 3 bytes [1, 2];
        // field 4 fixed64 -2.0.
        let mut b: Vec<u8> = vec![0x08, 0x03, 0x15];
        b.extend(1.0f32.to_le_bytes());
        b.extend([0x1a, 0x02, 0x01, 0x02, 0x21]);
        b.extend((-2.0f64).to_le_bytes());
        let mut buf = b.as_slice();
        assert_eq!(next_field(&mut buf), Some((1, Field::Varint(3))));
        let one = Field::Fixed32(1.0f32.to_le_bytes());
        assert_eq!(next_field(&mut buf), Some((2, one)));
        assert_eq!(next_field(&mut buf), Some((3, Field::Bytes(&[1, 2]))));
        let minus_two = Field::Fixed64((-2.0f64).to_le_bytes());
        assert_eq!(next_field(&mut buf), Some((4, minus_two)));
        assert!(buf.is_empty());
        // Field number 0, a group, bytes past the end, a fixed32 cut short.
        for bad in [
            &[0x00, 0x01][..],
            &[0x0b],
            &[0x0a, 0x05, 0x01],
            &[0x0d, 0x00, 0x00],
        ] {
            let mut buf = bad;
            assert_eq!(next_field(&mut buf), None, "{bad:?}");
        }
    }

    #[test]
    fn fixed_values_read_little_endian() {
        let mut b = 2.5f64.to_le_bytes().to_vec();
        b.push(9);
        assert_eq!(f64::read_fixed(&b), Some((2.5, &[9u8][..])));
        assert_eq!(f32::read_fixed(&b[..3]), None);
    }

    #[test]
    fn packed_arrays_copy_their_elements() {
        let values = [1.5f32, -0.0, f32::MAX, 3.25e-20];
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let mut v = vec![7.0f32];
        assert_eq!(packed_len::<f32>(Some(&bytes)), Some(4));
        f32::extend_packed(&mut v, &bytes);
        assert_eq!(v, [7.0, 1.5, -0.0, f32::MAX, 3.25e-20]);
        assert_eq!(packed_len::<f64>(Some(&bytes[..12])), None);
        assert_eq!(packed_len::<f64>(None), Some(0));
    }

    /// The copy and the element loop agree bit for bit (NaN payloads, a
    /// source at an odd address, an empty array), for both element types.
    #[test]
    fn the_packed_copy_reads_as_the_element_loop() {
        fn agree<T: Scalar + bytemuck::Pod, const N: usize>(src: &[u8], from: fn([u8; N]) -> T) {
            let (mut by_copy, mut by_loop) = (vec![T::default()], vec![T::default()]);
            T::extend_packed(&mut by_copy, src);
            extend_le(&mut by_loop, src, from);
            let bytes = |v: &[T]| bytemuck::cast_slice::<T, u8>(v).to_vec();
            assert_eq!(bytes(&by_copy), bytes(&by_loop));
            assert_eq!(by_copy.len(), 1 + src.len() / N);
        }
        let raw: Vec<u8> = (0u8..=255).cycle().take(1 + 8 * 37).collect();
        // Offset 1: no element of the source is aligned.
        let bytes = &raw[1..];
        let mut nan = f64::NAN.to_le_bytes().to_vec();
        nan[0] = 0x5a;
        for src in [bytes, &nan[..], &[][..]] {
            agree(src, f32::from_le_bytes);
            agree(src, f64::from_le_bytes);
        }
    }
}
