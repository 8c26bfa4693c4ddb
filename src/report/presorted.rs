//! The hook of "Depth-Presorted Triangle Lists" (duplication ratio and segment size against
//! partitions, preprocessing time against triangles). The presorted lists are not in
//! fragrace yet: until they are, the section says so and measures nothing. When they land,
//! this file measures them the way the other sections do (a `section` returning tables and
//! figures of measured runs), and nothing else in the report changes.

use super::{Paper, PaperConfig, Section};

/// Whether fragrace has the presorted lists (the registry has an algorithm of the family).
pub fn available() -> bool {
    fragrace_kernels::algorithms()
        .iter()
        .any(|a| a.info().family.contains("presorted"))
}

/// The section: what is missing, and how to regenerate it once it is there.
pub fn section(cfg: &PaperConfig) -> Section {
    let mut s = Section::new(Paper::Presorted, "Depth-presorted triangle lists");
    s.text.push(if available() {
        "The presorted lists are in the registry, but this report does not measure them \
         yet: this section's file (src/report/presorted.rs) is where their figures go."
            .into()
    } else {
        "Not measured: fragrace has no depth-presorted triangle lists yet, so there is no \
         duplication ratio, segment size or preprocessing time to report."
            .into()
    });
    s.text
        .push(format!("Command: {}", cfg.command(Paper::Presorted)));
    s
}
