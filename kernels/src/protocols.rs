//! The capture kernels of the synchronisation protocols, public for model checking only.
//!
//! `kernels/tests/loom/` runs these exact kernels (not copies) under loom, one loom thread
//! per invocation (`fragrace_emu::exec::run_on_threads`), and checks each protocol's
//! invariant under every interleaving loom explores. They are re-exported here rather than
//! from their families so that nothing else depends on them: an algorithm is built from the
//! registry ([`crate::algorithms`]), never from these pieces. Making them public changed no
//! behaviour: only visibility (`pub` structs and fields, `pub(crate)` family modules).
//!
//! - linked list: [`LlInsert`] on a [`ListPool`] (counter, head exchange, node write; with
//!   `publish_before_write` the planted bug, with `reader` an in-pass reader);
//! - count-scan-store A-buffers: [`CountKernel`], [`DfbStore`], [`SparseAllocate`], [`SbStore`];
//! - k-buffers: [`RmwStore`] (racy by design), [`Depth32`] + [`Claim32`] and [`Store64`] (the
//!   atomic-min chains, with their [`Census`]), [`SpinStore`] (spinlock), [`InterlockStore`]
//!   (pixel interlock), all on [`SplitSlots`] or key buffers;
//! - occupancy culling: [`OccupancyFill`] (atomic or plain OR into a pixel's map) and
//!   [`OccupancyCount`] (Kernighan's count, whose arithmetic is `occupancy::bits`).

pub use crate::abuffer::dfb::DfbStore;
pub use crate::abuffer::ll::{ListPool, LlInsert, NODE_WORDS};
pub use crate::abuffer::sb::{SbStore, SparseAllocate};
pub use crate::basic::CountKernel;
pub use crate::kbuffer::atomic::{Census, Claim32, Depth32, Store64};
pub use crate::kbuffer::interlock::InterlockStore;
pub use crate::kbuffer::rmw::RmwStore;
pub use crate::kbuffer::slots::SplitSlots;
pub use crate::kbuffer::spinlock::SpinStore;
pub use crate::occupancy::passes::{Count as OccupancyCount, Fill as OccupancyFill};
