//! The fill and count kernels of occupancy culling ("Improving k-buffer methods via
//! occupancy maps", section 2): each reads like the paper's description, the arithmetic is
//! [`super::bits`]. Public for the loom models only (`crate::protocols`).

use fragrace_emu::{
    Buf, CompareFunc, DepthState, Fragment, FragmentKernel, FragmentState, KernelInfo,
};

use super::bits::{bucket, bucket_bound, count_word, BITS_PER_WORD, NO_CULLING};
use super::FillMode;

/// The fill pass: "the j-th bit of the occupancy map is set to 1 for each arriving fragment
/// f falling within the corresponding sub-interval, via blending or atomic operations".
pub struct Fill {
    /// `d` words per pixel, pixel-major.
    pub map: Buf<u32>,
    pub near: Buf<f32>,
    pub far: Buf<f32>,
    pub d: u32,
    pub mode: FillMode,
}

impl FragmentKernel for Fill {
    fn info(&self) -> KernelInfo {
        KernelInfo::new(match self.mode {
            FillMode::Atomic => "occupancy-fill",
            FillMode::Plain => "occupancy-fill-plain",
        })
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        // The range was written by an earlier pass: read-only here.
        let zn = f.load(self.near, p).await;
        let zf = f.load(self.far, p).await;
        let j = bucket(f.depth(), zn, zf, self.d * BITS_PER_WORD);
        let word = p * self.d + j / BITS_PER_WORD;
        let bit = 1u32 << (j % BITS_PER_WORD);
        match self.mode {
            FillMode::Atomic => {
                f.atomic_or(self.map, word, bit).await;
            }
            FillMode::Plain => {
                // Read, OR, write back: another fragment's bit set in between is lost.
                let old = f.load(self.map, word).await;
                f.store(self.map, word, old | bit).await;
            }
        }
    }
}

/// The count pass (full screen): "count the number of 1s in the bit-array p.b ... by
/// Brian Kernighan's algorithm: count the number of times p.b & (p.b - 1) is performed in a
/// loop. When the counter reaches k, the algorithm halts and the current bucket's depth is
/// returned to the Z-buffer (O(k) time)". Fewer than k bits: nothing is culled.
pub struct Count {
    pub map: Buf<u32>,
    pub near: Buf<f32>,
    pub far: Buf<f32>,
    pub d: u32,
    pub k: u32,
}

impl Count {
    /// Depth test `ALWAYS` with writes: the kernel's depth lands in the depth buffer.
    pub fn state() -> FragmentState {
        let mut s = FragmentState::new();
        s.depth = DepthState {
            test: true,
            func: CompareFunc::Always,
            write: true,
        };
        s
    }
}

impl FragmentKernel for Count {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("occupancy-count").with_depth_write()
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let zn = f.load(self.near, p).await;
        let zf = f.load(self.far, p).await;
        let s = self.d * BITS_PER_WORD;
        let mut counter = 0;
        for w in 0..self.d {
            let word = f.load(self.map, p * self.d + w).await;
            if let Some(j) = count_word(word, self.k, &mut counter) {
                f.write_depth(bucket_bound(w * BITS_PER_WORD + j, zn, zf, s));
                return;
            }
        }
        f.write_depth(NO_CULLING);
    }
}
