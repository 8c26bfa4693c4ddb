//! The linked-list push that `benches/explore.rs` and `examples/explore_push.rs` explore
//! (the loom/shuttle peer's model): 4 invocations on one pixel take a node with a counter
//! `fetch_add` and publish it with a compare-exchange loop on the pixel's head. Included by
//! path in both (`#[path]`): one model, so that the example's instruction counts are the
//! bench's. Not an example of its own (cargo finds `examples/*.rs` and `examples/*/main.rs`).

use fragrace_emu::{Buf, Device, FragInput, Fragment, FragmentKernel, KernelInfo};

/// The push kernel and its buffers.
pub struct Push {
    pub counter: Buf<u32>,
    pub head: Buf<u32>,
    pub next: Buf<u32>,
}

impl FragmentKernel for Push {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("ll-push")
    }
    async fn shade(&self, f: impl Fragment) {
        let node = f.atomic_add(self.counter, 0, 1).await;
        let mut old = f.atomic_load(self.head, 0).await;
        loop {
            f.store(self.next, node, old).await;
            match f.atomic_compare_exchange(self.head, 0, old, node).await {
                Ok(_) => break,
                Err(cur) => old = cur,
            }
        }
    }
}

/// A device with the push's buffers (node 0 is "no node": the counter starts at 1), the
/// kernel, and its 4 fragments on one pixel.
pub fn push_model() -> (Device, Push, Vec<FragInput>) {
    let mut dev = Device::new();
    let counter = dev
        .buffer::<u32>("counter", 1)
        .expect("a 1-word buffer fits");
    let head = dev.buffer::<u32>("head", 1).expect("a 1-word buffer fits");
    let next = dev.buffer::<u32>("next", 5).expect("a 5-word buffer fits");
    dev.memory
        .write(counter, 0, &[1])
        .expect("word 0 of a 1-word buffer");
    let frags = (0..4)
        .map(|i| FragInput {
            primitive_id: i,
            coverage: 1,
            ..Default::default()
        })
        .collect();
    (
        dev,
        Push {
            counter,
            head,
            next,
        },
        frags,
    )
}
