//! Times as messages print them.

use std::fmt;

/// A time as a message prints it: a decimal of at most 12 significant digits
/// within four units in the last place of the value, so that a grid point
/// computed as `t₀ + n·H` reads as the grid gives it (`t = 107.338`, not
/// `107.33800000000001`). Other values (the times of adaptive steps) print in
/// full, the shortest decimal that reads back as the value, as do the
/// non-finite ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Time(pub f64);

/// How many units in the last place a time may be from the decimal printed.
const ULPS: f64 = 4.0;

/// The most significant digits of a decimal printed in place of the value.
const DIGITS: usize = 12;

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = self.0;
        if !t.is_finite() || t == 0.0 {
            return write!(f, "{t}");
        }
        let ulp = f64::from_bits(t.abs().to_bits() + 1) - t.abs();
        for digits in 0..DIGITS {
            let near: f64 = format!("{t:.digits$e}")
                .parse()
                .expect("Rust's exponent form reads back");
            if (near - t).abs() <= ULPS * ulp {
                return write!(f, "{near}");
            }
        }
        write!(f, "{t}")
    }
}

#[cfg(test)]
mod tests {
    use super::Time;

    #[test]
    fn grid_points_print_as_the_grid_gives_them() {
        let cases = [
            (107_338.0 * 1e-3, "107.338"),
            (0.1 + 0.2, "0.3"),
            (0.5, "0.5"),
            (0.0, "0"),
            (-3.0 * 0.1, "-0.3"),
            (1e-3, "0.001"),
            (400.0, "400"),
            (f64::NAN, "NaN"),
        ];
        for (t, shown) in cases {
            assert_eq!(Time(t).to_string(), shown, "{t:?}");
        }
        assert_eq!(format!("{}", 107_338.0 * 1e-3), "107.33800000000001");
    }

    #[test]
    fn times_far_from_a_short_decimal_print_in_full() {
        for t in [
            0.4870000000000123,
            0.49890883943400904,
            1.0 / 3.0,
            std::f64::consts::PI,
        ] {
            assert_eq!(Time(t).to_string(), t.to_string(), "{t:?}");
        }
    }
}
