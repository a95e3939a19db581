//! Tuning files: the solver schedule a run may override, as TOML (`foldfree param --tuning
//! FILE`, `foldfree volmap --tuning FILE`). The command line keeps what a user decides (input,
//! output, energy, solver, backend, cut, texture size, …); the knobs of the solvers live here,
//! in the library's own option types, one table each:
//!
//! ```toml
//! [admm]            # AdmmOptions: mu, max_iters, tol_primal, accel, recovery = "ls" | "bfs", …
//! mu = 200.0
//! accel = "anderson"
//!
//! [cut]             # CutOptions: seam_curvature, extra_seams, stretch_limit, overlap_splits
//! overlap_splits = 0
//!
//! [volmap]          # VolmapOptions: lambda_growth, max_rounds, … and one table per phase
//! max_rounds = 4
//! post = false      # an optional phase: a table of NewtonOptions, or false for none
//! [volmap.newton.cg]
//! preconditioner = "jacobi"
//! ```
//!
//! Every key is optional (a missing one keeps its default: a file with every default written
//! out gives the same run, byte for byte, as no file); an unknown key, a wrong type or a value
//! outside its range is bad input, reported with the file, line and key (exit 2 in the CLI).
//! [`Tuning::default_toml`] writes the complete default file (`foldfree dev tuning`).
#![forbid(unsafe_code)]

use std::ops::Range;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::param::admm::AdmmOptions;
use crate::param::cut::CutOptions;
use crate::vol::VolmapOptions;
use crate::{Error, OptionError, Result};

/// The solver knobs of the CLI's runs, one table per option type.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Tuning {
    /// `param`'s ADMM solver (its `energy` is the run's; `max_iters` is also `--max-iters`).
    pub admm: AdmmOptions,
    /// `param`'s cutting into charts (atlas path).
    pub cut: CutOptions,
    /// `volmap`'s pipeline (its Newton phases' `max_iters` are also `--max-iters`).
    pub volmap: VolmapOptions,
}

impl Tuning {
    /// Reads and checks a tuning file; errors (exit 2) name the file, the line and the key.
    pub fn from_file(path: &Path) -> Result<Tuning> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            Error::Usage(format!(
                "{}: cannot read the tuning file: {e}",
                path.display()
            ))
        })?;
        Tuning::from_toml(&text, path)
    }

    /// Parses and checks tuning text; `file` names it in errors.
    pub fn from_toml(text: &str, file: &Path) -> Result<Tuning> {
        let tuning: Tuning = toml::from_str(text).map_err(|e| {
            let at = e.span().map(|s| locate(text, s));
            Error::Usage(match at {
                Some((line, source)) => format!(
                    "{}:{line}: `{source}`: {}",
                    file.display(),
                    e.message().trim_end()
                ),
                None => format!("{}: {}", file.display(), e.message().trim_end()),
            })
        })?;
        tuning.validate().map_err(|(table, e)| {
            let path: Vec<&str> = std::iter::once(table).chain(e.key.split('.')).collect();
            let line = key_span(text, &path).map(|s| locate(text, s).0);
            Error::Usage(match line {
                Some(line) => format!("{}:{line}: [{table}] {e}", file.display()),
                None => format!("{}: [{table}] {e}", file.display()),
            })
        })?;
        Ok(tuning)
    }

    /// Checks every table's ranges; the error names the table (`admm`, `cut`, `volmap`).
    pub fn validate(&self) -> std::result::Result<(), (&'static str, OptionError)> {
        self.admm.validate().map_err(|e| ("admm", e))?;
        self.cut.validate().map_err(|e| ("cut", e))?;
        self.volmap.validate().map_err(|e| ("volmap", e))?;
        Ok(())
    }

    /// The complete default tuning as TOML, a starting point to edit (settings whose default
    /// depends on the energy, such as `admm.mu`, are left out: absent means "the energy's").
    pub fn default_toml() -> String {
        let body = toml::to_string(&Tuning::default()).unwrap_or_default();
        format!(
            "# foldfree tuning file (--tuning FILE.toml): every key with its default; delete what\n\
             # you do not change. Absent here, with energy-dependent defaults: [admm] mu,\n\
             # stall_checks, mu_shrink_max, aa_start. An optional phase of [volmap] is a table or\n\
             # false (none). README.md, \"Tuning files\".\n\n{body}"
        )
    }
}

/// 1-based line of `span.start` and that line's text, trimmed.
fn locate(text: &str, span: Range<usize>) -> (usize, String) {
    let start = span.start.min(text.len());
    let line = text[..start].matches('\n').count() + 1;
    let source = text.lines().nth(line - 1).unwrap_or("").trim().to_string();
    (line, source)
}

/// The span of the key at `path` (table names, then the key), if the text sets it.
fn key_span(text: &str, path: &[&str]) -> Option<Range<usize>> {
    use toml::de::{DeTable, DeValue};
    let root = DeTable::parse(text).ok()?;
    let mut table = root.get_ref();
    let (last, tables) = path.split_last()?;
    for name in tables {
        let (_, v) = table.iter().find(|(k, _)| k.get_ref() == name)?;
        match v.get_ref() {
            DeValue::Table(t) => table = t,
            _ => return None,
        }
    }
    let (k, _) = table.iter().find(|(k, _)| k.get_ref() == last)?;
    Some(k.span())
}

/// `#[serde(with)]` for an optional phase of a pipeline: a table of its options, or `false`
/// for none (TOML has no null). A missing key keeps the default.
pub(crate) mod phase {
    use serde::de::{self, Deserializer, MapAccess, Visitor};
    use serde::{Deserialize, Serialize, Serializer};

    pub fn serialize<T: Serialize, S: Serializer>(
        v: &Option<T>,
        s: S,
    ) -> std::result::Result<S::Ok, S::Error> {
        match v {
            Some(t) => t.serialize(s),
            None => s.serialize_bool(false),
        }
    }

    pub fn deserialize<'de, T: Deserialize<'de>, D: Deserializer<'de>>(
        d: D,
    ) -> std::result::Result<Option<T>, D::Error> {
        struct Phase<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for Phase<T> {
            type Value = Option<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table of the phase's options, or false for none")
            }
            fn visit_bool<E: de::Error>(self, b: bool) -> std::result::Result<Self::Value, E> {
                if b {
                    Err(E::invalid_value(de::Unexpected::Bool(true), &self))
                } else {
                    Ok(None)
                }
            }
            fn visit_map<A: MapAccess<'de>>(
                self,
                map: A,
            ) -> std::result::Result<Self::Value, A::Error> {
                T::deserialize(de::value::MapAccessDeserializer::new(map)).map(Some)
            }
        }
        d.deserialize_any(Phase(std::marker::PhantomData))
    }
}
