//! The command line's option groups of `curve` and `generate`, compiled here from the same
//! source files, so that the keyword arguments of `polyspline.curve` and
//! `polyspline.generate` are the command line's options: the same names, defaults, parsing
//! and checks.

// Only the option groups and the file job are used here; the rest of these files serves the
// command line.
#[allow(dead_code)]
#[path = "../../src/cli/args.rs"]
mod args;
#[allow(dead_code)]
#[path = "../../src/cli/curve.rs"]
pub(crate) mod curve;
#[allow(dead_code)]
#[path = "../../src/cli/generate.rs"]
pub(crate) mod generate;
#[cfg(feature = "mpi")]
#[allow(dead_code)]
#[path = "../../src/cli/launch.rs"]
mod launch;
#[allow(dead_code)]
#[path = "../../src/cli/values.rs"]
mod values;

use args::{ElasticArgs, FeatureArgs, KnotArgs, PeriodicArgs};
