//! Datasets of many files (issue 16): a directory of ordinary containers, one per tile, and a
//! manifest that places them in one sample grid and makes a change to several of them
//! atomic. The design, with the commit protocol's correctness argument, is
//! `docs/datasets-design.md`; this module grows room by room as it is built.
//!
//! Built so far: [`placement`], where the tiles lie (a layout, or their georeferences) and
//! which edges they share; [`seams`], whether neighbours agree on a shared edge, and how a
//! policy settles them when they do not.

pub mod placement;
pub mod seams;
