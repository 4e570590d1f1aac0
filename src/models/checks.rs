//! What every model's params check shares: the limits of a run (work, memory, the window of
//! dimensional inputs), errors at JSON paths, and their wording.

use serde::de::DeserializeOwned;
use serde_json::Value;

/// Work per `advance` call: ~10 ms of trials, so interruption and checkpoints are prompt.
pub const WORK_CHUNK: u64 = 1 << 20;

/// Problems in a model's params: (JSON pointer, message).
pub type ParamErrors = Vec<(String, String)>;

/// Check a velocity range [v_min, v_max] (finite, v_min < v_max) at JSON pointer `at`.
pub fn check_velocity_range(range: [f64; 2], at: String, errors: &mut ParamErrors) {
    if !(range[0] < range[1] && range[0].is_finite() && range[1].is_finite()) {
        errors.push((
            at,
            format!("expected [v_min, v_max] with v_min < v_max, got {range:?}"),
        ));
    }
}

/// The most memory one run may need, as its model estimates it from its parameters (1 TiB):
/// a manifest asking for more is invalid on any machine (a typo, most likely). `run` also
/// refuses a run that does not fit in this machine's memory (`campaign::resources`).
pub const MAX_RUN_MEMORY: u64 = 1 << 40;

/// The window of every dimensional input of a model (masses, diameters, temperatures,
/// number densities, lengths, forces): 30 orders of magnitude either side of 1. Any physical
/// system in sensible units lies well inside (SI grains of nanometres to metres, reduced
/// units ~1); within it every product the engines and the theory form (n sigma^2 sqrt(T/m) t,
/// the energy of 2^32 particles, a temperature cooled by 1e-60 over 1e30 collision times, v^4
/// for a2, a spring force over a mass) stays far inside a double's range (1e+-308). Beyond
/// it, e.g. a DSMC `n1` of 1e308, the collision rate overflows.
pub const SCALE_MIN: f64 = 1e-30;
/// See [`SCALE_MIN`].
pub const SCALE_MAX: f64 = 1e30;

/// The most work one run may do, in its model's work units (the `runs` table's `trials`:
/// RFM particle steps, bisection and cascade grid cells, SPM walk steps, ...), as its
/// model's `check` counts it from the parameters: 10^15, about 10^7 CPU seconds (four months)
/// at the ~10^8 units per second of a `WORK_CHUNK` in ~10 ms. A run of more would never end
/// (`realisations` 1.8e19 was accepted and ran for ever).
pub const MAX_RUN_WORK: f64 = 1e15;

/// `value` with every whole number written as a float (`2.0`, `2e0`, `-3.0`) written as an
/// integer: a number is its value, so a whole-number parameter takes `2.0` as `2` (before: an
/// error) and a real-valued one reads the same double either way. Only where that is exact:
/// |x| < 2^53, and not -0.0 (whose sign a real-valued parameter keeps).
pub fn numbers_by_value(mut value: Value) -> Value {
    fn walk(v: &mut Value) {
        match v {
            Value::Array(a) => a.iter_mut().for_each(walk),
            Value::Object(m) => m.values_mut().for_each(walk),
            Value::Number(n) if n.is_f64() => {
                let x = n.as_f64().unwrap_or(f64::NAN);
                if x.fract() == 0.0
                    && x.abs() < 9007199254740992.0
                    && !(x == 0.0 && x.is_sign_negative())
                {
                    *v = Value::from(x as i64);
                }
            }
            _ => {}
        }
    }
    walk(&mut value);
    value
}

/// `value` deserialised as `T`; an error names the JSON pointer of the offending value (below
/// `path`), e.g. `/seed` for `"seed": 42.0`, which the schema takes for an integer.
pub fn from_value_at<T: DeserializeOwned>(value: Value, path: &str) -> Result<T, (String, String)> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let mut at = path.to_string();
        for seg in e.path().iter() {
            use serde_path_to_error::Segment;
            match seg {
                Segment::Seq { index } => at.push_str(&format!("/{index}")),
                Segment::Map { key } | Segment::Enum { variant: key } => {
                    at.push('/');
                    at.push_str(&key.replace('~', "~0").replace('/', "~1"));
                }
                Segment::Unknown => {}
            }
        }
        let mut message = e.inner().to_string();
        // serde_json appends " at line L column C", meaningless for a value.
        if let Some(i) = message.find(" at line ") {
            message.truncate(i);
        }
        if message.starts_with("invalid type: floating point") {
            message.push_str(" (an integer is written without a decimal point or exponent)");
        }
        (at, message)
    })
}

/// Bytes in words: `1.5 GB` (powers of 1000, as the memory messages of `resources`).
pub fn bytes_text(b: u64) -> String {
    let b = b as f64;
    if b >= 1e12 {
        format!("{:.1} TB", b / 1e12)
    } else if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else {
        format!("{:.1} MB", b / 1e6)
    }
}
