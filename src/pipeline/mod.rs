//! The pipeline `run` and `process` share: a source's frames → the
//! measurement → sinks (link, log, records).
//!
//! - `input` opens the source an address names (the same `source` types
//!   for both commands; a folder's capture times are a timing policy), picks
//!   the camera and checks the first frame against it.
//! - `stage` measures one frame and hands the result to the link and the
//!   log: the one place both commands measure.
//! - `live` is `run`'s wiring (threads, bounded queues, pacing, skip
//!   policy), with `pacing`, `closed_loop` (SITL), `signals`,
//!   `threads` (measurement, link events), `meters` (the one set of
//!   counters), [`status`] (the terminal line)
//!   and `provenance` (the log's metadata record) in files of their own.
//!
//! `process` runs the same input and stage in one thread, frame by frame
//! (`commands::process`). See ARCHITECTURE.md for the picture.

pub(crate) mod closed_loop;
pub(crate) mod input;
pub(crate) mod live;
pub(crate) mod meters;
pub(crate) mod pacing;
pub(crate) mod provenance;
pub(crate) mod signals;
pub(crate) mod stage;
pub mod status;
pub(crate) mod threads;
