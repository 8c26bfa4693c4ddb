//! Partitions saved as they finish, so that an interrupted preprocessing resumes where it
//! stopped instead of starting over: each partition's graph of a 48K-triangle mesh takes
//! hours (the occlusion graph is most of the work, and partitions are independent).
//!
//! A partition's file holds its segment and its statistics under a key: a hash of
//! everything its result depends on (this format's version, the method, the partition
//! count, which partition, and every piece's coordinates in the mesh's normalized frame, so
//! another mesh, another split of crossing triangles or another round of cutting cycles
//! gives another key). A file is used only when its name and stored key match, its checksum
//! passes and it decodes whole; anything else is ignored and the partition computed again:
//! a checkpoint is never trusted on its name alone. Files are written atomically (temporary
//! file, sync, rename, as [`super::file::save`]), so an interrupted write leaves none under
//! a checkpoint's name. Only partitions that succeeded are saved.
//!
//! A partition resolved by cells ([`super::Method::Cells`]) also keeps its occlusion
//! graph's strongly connected components, with the edges inside each
//! ([`super::cells::Components`]), as soon as they are known: the graph is the hours of
//! the work, so a partition whose cells fail (for memory, say) is resumed at its cells.

use std::path::{Path, PathBuf};
use std::time::Duration;

use glam::DVec3;

use super::file::{encode_segment, fnv, write_atomic, FileError, Reader};
use super::{Method, PartitionStats, Segment};

/// What a components checkpoint keeps of a partition's graph besides its components:
/// what the partition's statistics need.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GraphFacts {
    /// The graph's nodes and edges.
    pub nodes: usize,
    pub edges: usize,
    /// The time the graph took.
    pub graph_time: Duration,
}

/// A partition's graph as a components checkpoint keeps it: the graph nodes of each
/// strongly connected component (in the draw order of the condensation) and the edges
/// inside each, as indices into it ([`super::cells::Components`]).
pub type SavedComponents = (GraphFacts, Vec<Vec<usize>>, Vec<Vec<(u32, u32)>>);

const MAGIC: &[u8; 8] = b"FRPRPART";
const COMPONENTS_MAGIC: &[u8; 8] = b"FRPRCOMP";
const VERSION: u32 = 1;

/// A directory of finished partitions.
#[derive(Clone, Debug)]
pub struct Checkpoints {
    dir: PathBuf,
}

/// What a partition's result depends on, hashed ([`Checkpoints::key`]).
pub struct KeyInput<'a> {
    /// The pieces in the mesh's normalized frame (what the graphs are built from).
    pub tris: &'a [[DVec3; 3]],
    pub partitions: usize,
    pub partition: usize,
    pub method: Method,
}

impl Checkpoints {
    /// Partitions kept in `dir` (created when the first is saved).
    pub fn new(dir: impl Into<PathBuf>) -> Checkpoints {
        Checkpoints { dir: dir.into() }
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The key of one partition's result.
    pub fn key(k: &KeyInput) -> u64 {
        let mut b: Vec<u8> = Vec::with_capacity(16 + k.tris.len() * 72);
        b.extend_from_slice(&VERSION.to_le_bytes());
        b.push(match k.method {
            Method::Cells => 0,
            Method::Scan => 1,
        });
        b.extend_from_slice(&(k.partitions as u32).to_le_bytes());
        b.extend_from_slice(&(k.partition as u32).to_le_bytes());
        for t in k.tris {
            for v in t {
                for c in v.to_array() {
                    b.extend_from_slice(&c.to_bits().to_le_bytes());
                }
            }
        }
        fnv(&b)
    }

    fn path(&self, partition: usize, key: u64) -> PathBuf {
        self.dir.join(format!("partition-{partition}-{key:016x}"))
    }

    fn components_path(&self, partition: usize, key: u64) -> PathBuf {
        self.dir.join(format!("components-{partition}-{key:016x}"))
    }

    /// The file at `path` decoded by `decode`, `None` when there is none.
    fn read<T>(
        path: &Path,
        decode: impl FnOnce(&[u8], &Path) -> Result<T, FileError>,
    ) -> Option<Result<T, FileError>> {
        match std::fs::read(path) {
            Ok(b) => Some(decode(&b, path)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(source) => Some(Err(FileError::Io {
                path: path.to_path_buf(),
                source,
            })),
        }
    }

    /// `body` under a header (magic, version, key) and followed by its checksum, written
    /// atomically to `path` (the directory made first).
    fn write(&self, path: &Path, magic: &[u8; 8], key: u64, body: &[u8]) -> Result<(), FileError> {
        std::fs::create_dir_all(&self.dir).map_err(|source| FileError::Io {
            path: self.dir.clone(),
            source,
        })?;
        let mut b: Vec<u8> = Vec::with_capacity(body.len() + 28);
        b.extend_from_slice(magic);
        b.extend_from_slice(&VERSION.to_le_bytes());
        b.extend_from_slice(&key.to_le_bytes());
        b.extend_from_slice(body);
        let sum = fnv(&b);
        b.extend_from_slice(&sum.to_le_bytes());
        write_atomic(path, &b)
    }

    /// The saved components of `partition`'s graph under `key`, if a valid file is there
    /// for a graph of `nodes` nodes; `Err` only names why a file that is there was not used.
    pub fn load_components(
        &self,
        partition: usize,
        key: u64,
        nodes: usize,
    ) -> Option<Result<SavedComponents, FileError>> {
        Checkpoints::read(&self.components_path(partition, key), |b, path| {
            decode_components(b, path, key, nodes)
        })
    }

    /// Saves the components of `partition`'s graph under `key` (`comps` and `inner` as
    /// [`SavedComponents`] holds them).
    pub fn save_components(
        &self,
        partition: usize,
        key: u64,
        facts: &GraphFacts,
        comps: &[Vec<usize>],
        inner: &[Vec<(u32, u32)>],
    ) -> Result<(), FileError> {
        let edges: usize = inner.iter().map(Vec::len).sum();
        let mut b: Vec<u8> = Vec::with_capacity(28 + 4 * (facts.nodes + comps.len()) + 8 * edges);
        let nanos = facts.graph_time.as_nanos().min(u128::from(u64::MAX)) as u64;
        for w in [facts.nodes as u64, facts.edges as u64, nanos] {
            b.extend_from_slice(&w.to_le_bytes());
        }
        b.extend_from_slice(&(comps.len() as u32).to_le_bytes());
        for (comp, inner) in comps.iter().zip(inner) {
            b.extend_from_slice(&(comp.len() as u32).to_le_bytes());
            for &x in comp {
                b.extend_from_slice(&(x as u32).to_le_bytes());
            }
            b.extend_from_slice(&(inner.len() as u32).to_le_bytes());
            for &(i, j) in inner {
                b.extend_from_slice(&i.to_le_bytes());
                b.extend_from_slice(&j.to_le_bytes());
            }
        }
        let path = self.components_path(partition, key);
        self.write(&path, COMPONENTS_MAGIC, key, &b)
    }

    /// The saved result of `partition` under `key`, if a valid one is there; `Err` only
    /// names why a file that is there was not used (the caller computes it again).
    pub fn load(
        &self,
        partition: usize,
        key: u64,
        npieces: u32,
    ) -> Option<Result<(Segment, PartitionStats), FileError>> {
        Checkpoints::read(&self.path(partition, key), |b, path| {
            decode(b, path, key, npieces)
        })
    }

    /// Saves `partition`'s result under `key`.
    pub fn save(
        &self,
        partition: usize,
        key: u64,
        segment: &Segment,
        stats: &PartitionStats,
    ) -> Result<(), FileError> {
        let mut b: Vec<u8> = Vec::new();
        encode_segment(segment, &mut b);
        for x in stat_words(stats) {
            b.extend_from_slice(&x.to_le_bytes());
        }
        self.write(&self.path(partition, key), MAGIC, key, &b)
    }

    /// Removes the directory and every checkpoint in it (once the whole result is saved).
    pub fn remove(&self) -> Result<(), FileError> {
        match std::fs::remove_dir_all(&self.dir) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(FileError::Io {
                path: self.dir.clone(),
                source: e,
            }),
            _ => Ok(()),
        }
    }
}

/// Statistics stored with a segment, as words in a fixed order ([`stats_of`] reads them):
/// the node, edge and back-edge counts, the scan's and the cells' counts
/// ([`count_words`]), the graph's and the scan's times in nanoseconds.
const STAT_WORDS: usize = 18;

/// The scan's and the cells' counts, in the order they are stored.
fn count_words(s: &mut PartitionStats) -> [&mut u64; 13] {
    let (n, c) = (&mut s.scan, &mut s.cells);
    [
        &mut n.moves,
        &mut n.splits,
        &mut n.pairwise,
        &mut n.bf_dups,
        &mut n.whole_moves,
        &mut n.lp_calls,
        &mut n.touching_tests,
        &mut n.touching_planes,
        &mut c.cyclic_components,
        &mut c.largest_component,
        &mut c.cuts,
        &mut c.prefix_cuts,
        &mut c.max_depth,
    ]
}

fn stat_words(s: &PartitionStats) -> [u64; STAT_WORDS] {
    let nanos = |d: Duration| d.as_nanos().min(u128::from(u64::MAX)) as u64;
    let mut w = [0u64; STAT_WORDS];
    w[0] = s.initial_nodes as u64;
    w[1] = s.edges as u64;
    w[2] = s.back_edges as u64;
    let mut copy = s.clone();
    for (to, from) in w[3..16].iter_mut().zip(count_words(&mut copy)) {
        *to = *from;
    }
    w[16] = nanos(s.graph_time);
    w[17] = nanos(s.scan_time);
    w
}

fn stats_of(w: [u64; STAT_WORDS]) -> PartitionStats {
    let mut s = PartitionStats {
        initial_nodes: w[0] as usize,
        edges: w[1] as usize,
        back_edges: w[2] as usize,
        graph_time: Duration::from_nanos(w[16]),
        scan_time: Duration::from_nanos(w[17]),
        resumed: true,
        ..Default::default()
    };
    for (to, from) in count_words(&mut s).into_iter().zip(&w[3..16]) {
        *to = *from;
    }
    s
}

/// The body of a checkpoint file after its header (`magic`, version, `key`), its checksum
/// checked; a reader over the whole file positioned after the header, and the body's end.
fn open<'a>(
    bytes: &'a [u8],
    path: &'a Path,
    magic: &[u8; 8],
    key: u64,
) -> Result<(Reader<'a>, usize), FileError> {
    let corrupt = |what: String| FileError::Corrupt {
        path: path.to_path_buf(),
        what,
    };
    if bytes.len() < 28 || &bytes[..8] != magic {
        return Err(FileError::Format {
            path: path.to_path_buf(),
            version: 0,
        });
    }
    let (body, sum) = bytes.split_at(bytes.len() - 8);
    if fnv(body) != u64::from_le_bytes(sum.try_into().expect("8 bytes")) {
        return Err(corrupt("checksum mismatch".into()));
    }
    let mut r = Reader::new(body, 8, path);
    let version = r.u32()?;
    if version != VERSION {
        return Err(corrupt(format!(
            "checkpoint version {version}, expected {VERSION}"
        )));
    }
    let stored = r.u64()?;
    if stored != key {
        return Err(corrupt(format!("key {stored:016x}, expected {key:016x}")));
    }
    Ok((r, body.len()))
}

/// That `r` has read the whole body.
fn at_end(r: &Reader, end: usize, path: &Path) -> Result<(), FileError> {
    if r.at() != end {
        return Err(FileError::Corrupt {
            path: path.to_path_buf(),
            what: format!("{} trailing bytes", end - r.at()),
        });
    }
    Ok(())
}

fn decode(
    bytes: &[u8],
    path: &Path,
    key: u64,
    npieces: u32,
) -> Result<(Segment, PartitionStats), FileError> {
    let (mut r, end) = open(bytes, path, MAGIC, key)?;
    let segment = r.segment(npieces)?;
    let mut w = [0u64; STAT_WORDS];
    for x in &mut w {
        *x = r.u64()?;
    }
    at_end(&r, end, path)?;
    Ok((segment, stats_of(w)))
}

fn decode_components(
    bytes: &[u8],
    path: &Path,
    key: u64,
    nodes: usize,
) -> Result<SavedComponents, FileError> {
    let corrupt = |what: String| FileError::Corrupt {
        path: path.to_path_buf(),
        what,
    };
    let (mut r, end) = open(bytes, path, COMPONENTS_MAGIC, key)?;
    let stored_nodes = r.u64()?;
    if stored_nodes != nodes as u64 {
        return Err(corrupt(format!(
            "a graph of {stored_nodes} nodes, expected {nodes}"
        )));
    }
    let edges = r.u64()? as usize;
    let graph_time = Duration::from_nanos(r.u64()?);
    let count = r.u32()? as usize;
    // Every node in exactly one component, every edge between two of its nodes.
    let mut seen = vec![false; nodes];
    let (mut comps, mut inner) = (Vec::new(), Vec::new());
    for _ in 0..count {
        let len = r.u32()? as usize;
        if len == 0 || len > nodes {
            return Err(corrupt(format!("a component of {len} nodes")));
        }
        let mut comp = Vec::with_capacity(len);
        for _ in 0..len {
            let x = r.u32()? as usize;
            if x >= nodes || std::mem::replace(&mut seen[x], true) {
                return Err(corrupt(format!("node {x} out of range or twice")));
            }
            comp.push(x);
        }
        let m = r.u32()? as usize;
        let mut es = Vec::with_capacity(m.min((end - r.at()) / 8));
        for _ in 0..m {
            let (i, j) = (r.u32()?, r.u32()?);
            if i as usize >= len || j as usize >= len {
                return Err(corrupt(format!("edge {i} -> {j} in a component of {len}")));
            }
            es.push((i, j));
        }
        comps.push(comp);
        inner.push(es);
    }
    if seen.iter().any(|s| !s) {
        return Err(corrupt("a node in no component".into()));
    }
    at_end(&r, end, path)?;
    let facts = GraphFacts {
        nodes,
        edges,
        graph_time,
    };
    Ok((facts, comps, inner))
}
