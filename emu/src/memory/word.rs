//! The words a buffer holds, the typed handles kernels name buffers by, global word
//! addresses, and per-pixel arrays (the layout kernels declare for prefetching).

use std::fmt;
use std::marker::PhantomData;

/// A word type a buffer can hold.
pub trait Word:
    Copy + Unpin + PartialEq + fmt::Debug + Send + Sync + 'static + sealed::Sealed
{
    /// True for 64-bit words.
    const WIDE: bool;
    const NAME: &'static str;
    const KIND: WordKind;
    fn to_bits(self) -> u64;
    fn from_bits(bits: u64) -> Self;
}

/// The word types, for dispatch in generic code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WordKind {
    U32,
    I32,
    F32,
    U64,
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for u32 {}
    impl Sealed for i32 {}
    impl Sealed for f32 {}
    impl Sealed for u64 {}
}

impl Word for u32 {
    const WIDE: bool = false;
    const NAME: &'static str = "u32";
    const KIND: WordKind = WordKind::U32;
    fn to_bits(self) -> u64 {
        self as u64
    }
    fn from_bits(bits: u64) -> Self {
        bits as u32
    }
}
impl Word for i32 {
    const WIDE: bool = false;
    const NAME: &'static str = "i32";
    const KIND: WordKind = WordKind::I32;
    fn to_bits(self) -> u64 {
        self as u32 as u64
    }
    fn from_bits(bits: u64) -> Self {
        bits as u32 as i32
    }
}
impl Word for f32 {
    const WIDE: bool = false;
    const NAME: &'static str = "f32";
    const KIND: WordKind = WordKind::F32;
    fn to_bits(self) -> u64 {
        self.to_bits() as u64
    }
    fn from_bits(bits: u64) -> Self {
        f32::from_bits(bits as u32)
    }
}
impl Word for u64 {
    const WIDE: bool = true;
    const NAME: &'static str = "u64";
    const KIND: WordKind = WordKind::U64;
    fn to_bits(self) -> u64 {
        self
    }
    fn from_bits(bits: u64) -> Self {
        bits
    }
}

/// A typed handle to a buffer of a [`Memory`]. Cheap to copy into kernel structs.
pub struct Buf<T> {
    pub(crate) id: u32,
    pub(crate) len: u32,
    _t: PhantomData<fn() -> T>,
}

impl<T> Clone for Buf<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for Buf<T> {}
impl<T> fmt::Debug for Buf<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Buf#{}[{}]", self.id, self.len)
    }
}

impl<T: Word> Buf<T> {
    /// Number of words.
    pub fn len(&self) -> u32 {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    pub fn id(&self) -> u32 {
        self.id
    }
}

impl<T> Buf<T> {
    /// The handle of buffer `id` of `len` words (for the memory that creates it).
    pub(super) fn new(id: u32, len: u32) -> Self {
        Buf {
            id,
            len,
            _t: PhantomData,
        }
    }
}

/// A global word address: buffer id in the high 32 bits, word index in the low 32.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    serde::Serialize,
    serde::Deserialize,
)]
pub struct Addr(pub u64);

impl Addr {
    pub fn new(buffer: u32, index: u32) -> Addr {
        Addr(((buffer as u64) << 32) | index as u64)
    }
    pub fn buffer(self) -> u32 {
        (self.0 >> 32) as u32
    }
    pub fn index(self) -> u32 {
        self.0 as u32
    }
}

/// A per-pixel array of a storage buffer: pixel `p`'s slot starts at word `p * stride`
/// (`p` as [`Fragment::pixel_index`]).
///
/// [`Fragment::pixel_index`]: crate::Fragment::pixel_index
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelArray {
    /// The buffer's id ([`Buf::id`]).
    pub buffer: u32,
    /// Words per pixel.
    pub stride: u32,
}

/// A per-block array of a storage buffer: the screen is cut into square blocks of
/// `2^shift` pixels a side, row-major from the top left (`width.div_ceil(2^shift)` blocks
/// a row), and block `b`'s slot starts at word `b * stride` (a counter per screen block).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlockArray {
    /// The buffer's id ([`Buf::id`]).
    pub buffer: u32,
    /// log2 of a block's side in pixels.
    pub shift: u32,
    /// Words per block.
    pub stride: u32,
}

impl BlockArray {
    /// The first word of the slot of the block holding pixel `(x, y)` of a frame `width`
    /// pixels wide.
    #[inline(always)]
    pub fn first_word(&self, x: u32, y: u32, width: u32) -> u64 {
        let across = u64::from(width.div_ceil(1 << self.shift.min(31)));
        (u64::from(y >> self.shift.min(31)) * across + u64::from(x >> self.shift.min(31)))
            * u64::from(self.stride)
    }
}
