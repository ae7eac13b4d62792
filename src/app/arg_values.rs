//! The values of the flags that name a method or a registration, each with its help line: the argument
//! parsers of `calibrate`, `calibrate curve` and `real_data` take them from here, so a method name is parsed
//! once, at the edge.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};

use crate::calib::registry::MethodKind;
use crate::eval::transfer::TestRegistration;

/// `calibrate --method`'s values, each with what the method is, as `--help` lists them; parsed once, here.
pub fn method_values() -> impl TypedValueParser<Value = MethodKind> {
    PossibleValuesParser::new(
        MethodKind::ALL.map(|m| PossibleValue::new(m.name()).help(m.info().summary)),
    )
    .try_map(|name| MethodKind::parse(&name))
}

/// `calibrate --test-registration`'s values.
pub fn registration_values() -> impl TypedValueParser<Value = TestRegistration> {
    PossibleValuesParser::new([
        PossibleValue::new("refit").help(
            "the test campaign's tracker frame and probe mounting, registered on its own points (another \
             station, another day)",
        ),
        PossibleValue::new("model").help("the model's registration (same station and probe)"),
    ])
    .try_map(|name| TestRegistration::parse(&name))
}
