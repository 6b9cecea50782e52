//! Keyword arguments onto the command line's option groups: each keyword is the option's
//! name with `_` for `-` (`kink_angle=20` is `--kink-angle=20`), parsed by the same clap
//! definitions, so names, defaults, value parsing and messages are the command line's.
//!
//! A keyword that names no option is a `TypeError`; a flag takes `True`/`False`; `None`
//! leaves an option at its default; every other value is passed as `str(value)`. Parse errors
//! are `polyspline.ParameterError` (a `ValueError`) with clap's one-line message.

use clap::{ArgAction, ArgMatches, Args, Command, FromArgMatches};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict};
use std::ffi::OsString;

/// The command the group `T` parses with (its arguments only, no program name).
fn command<T: Args>() -> Command {
    T::augment_args(
        Command::new("polyspline curve")
            .no_binary_name(true)
            .color(clap::ColorChoice::Never)
            .disable_help_flag(true),
    )
}

/// The arguments `options` stands for, for group `T`; `reserved` are ids passed otherwise.
pub(crate) fn argv<T: Args>(
    py: Python<'_>,
    options: &Bound<'_, PyDict>,
    reserved: &[&str],
) -> PyResult<Vec<String>> {
    let command = command::<T>();
    let mut argv = Vec::new();
    for (key, value) in options.iter() {
        let key: String = key.extract()?;
        let arg = command
            .get_arguments()
            .find(|a| a.get_id() == key.as_str() && !a.is_positional())
            .filter(|_| !reserved.contains(&key.as_str()));
        let (Some(arg), Some(long)) = (arg, arg.and_then(|a| a.get_long())) else {
            return Err(PyTypeError::new_err(format!(
                "unexpected keyword argument '{key}' (not an option of this call; see polyspline.options())"
            )));
        };
        if value.is_none() {
            continue;
        }
        if matches!(arg.get_action(), ArgAction::SetTrue) {
            let Ok(flag) = value.cast::<PyBool>() else {
                return Err(super::error(
                    py,
                    "ParameterError",
                    format!(
                        "--{long}: a flag; pass True or False, not {}",
                        value.repr()?
                    ),
                ));
            };
            if flag.is_true() {
                argv.push(format!("--{long}"));
            }
        } else {
            argv.push(format!("--{long}={}", value.str()?));
        }
    }
    Ok(argv)
}

/// Parse `argv` into group `T`, as the command line would.
pub(crate) fn parse<T: Args + FromArgMatches>(py: Python<'_>, argv: Vec<OsString>) -> PyResult<T> {
    Ok(parse_matches(py, argv)?.0)
}

/// [`parse`], with the matches (which tell the options given from those left at defaults).
pub(crate) fn parse_matches<T: Args + FromArgMatches>(
    py: Python<'_>,
    argv: Vec<OsString>,
) -> PyResult<(T, ArgMatches)> {
    let message = |e: clap::Error| {
        let text = e.to_string();
        let line = text.lines().next().unwrap_or_default();
        let line = line.strip_prefix("error: ").unwrap_or(line).to_string();
        super::error(py, "ParameterError", line)
    };
    let matches = command::<T>().try_get_matches_from(argv).map_err(message)?;
    let parsed = T::from_arg_matches(&matches).map_err(message)?;
    Ok((parsed, matches))
}

/// Option id → default value as the command line spells it (`None`: no default; flags:
/// `False`).
pub(crate) fn defaults<'py, T: Args>(py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    for arg in command::<T>().get_arguments() {
        if arg.is_positional() || arg.get_long().is_none() {
            continue;
        }
        let id = arg.get_id().as_str();
        if matches!(arg.get_action(), ArgAction::SetTrue) {
            out.set_item(id, false)?;
        } else {
            let d: Vec<String> = arg
                .get_default_values()
                .iter()
                .map(|v| v.to_string_lossy().into_owned())
                .collect();
            match d.as_slice() {
                [one] => out.set_item(id, one)?,
                _ => out.set_item(id, py.None())?,
            }
        }
    }
    Ok(out)
}
