//! Every algorithm, by name. Adding an algorithm means adding one line here; the CLI, the
//! differential test harness and the fuzzer pick it up.

use crate::algo::Algorithm;
use crate::basic;

/// Every algorithm, in catalogue order.
pub fn algorithms() -> Vec<Box<dyn Algorithm>> {
    let mut v: Vec<Box<dyn Algorithm>> = vec![
        Box::new(basic::Count),
        Box::new(basic::CountPlain),
        Box::new(basic::Opaque),
        Box::new(basic::Truth),
    ];
    v.extend(crate::abuffer::algorithms());
    v.extend(crate::kbuffer::algorithms());
    v.extend(crate::peeling::algorithms());
    v.extend(crate::merging::algorithms());
    v.extend(crate::bucket::algorithms());
    v
}

/// The algorithm called `name`.
pub fn algorithm(name: &str) -> Option<Box<dyn Algorithm>> {
    algorithms().into_iter().find(|a| a.info().name == name)
}

/// All names.
pub fn names() -> Vec<&'static str> {
    algorithms().iter().map(|a| a.info().name).collect()
}
