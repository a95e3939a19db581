//! clap glue for the library's option types (`cli` feature): the enums the command line takes
//! that clap cannot derive for (a variant with data).
#![forbid(unsafe_code)]

use clap::builder::PossibleValue;

use crate::init::tutte::TutteWeights;
use crate::init::InitMethod;

/// `--init tutte | tutte-mean-value | lscm`.
impl clap::ValueEnum for InitMethod {
    fn value_variants<'a>() -> &'a [Self] {
        &[
            InitMethod::Tutte(TutteWeights::Uniform),
            InitMethod::Tutte(TutteWeights::MeanValue),
            InitMethod::Lscm,
        ]
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        Some(match self {
            InitMethod::Tutte(TutteWeights::Uniform) => PossibleValue::new("tutte")
                .help("Tutte embedding, uniform weights (flip-free on a convex boundary)"),
            InitMethod::Tutte(TutteWeights::MeanValue) => PossibleValue::new("tutte-mean-value")
                .help("Tutte embedding with Floater's mean-value weights"),
            InitMethod::Lscm => PossibleValue::new("lscm")
                .help("Least-squares conformal map (may flip a few faces; ADMM repairs them)"),
        })
    }
}
