//! Typed pieces of generated expressions. Each prints itself as Rust source; the templates put
//! them into statements, so the code's structure lives in the templates and no text is patched.

use std::fmt;

/// A float as a Rust literal that reads back to exactly the same value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FloatLit(pub f64);

impl fmt::Display for FloatLit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let text = format!("{:?}", self.0);
        if text.contains(['.', 'e', 'E', 'N', 'i']) {
            f.write_str(&text)
        } else {
            write!(f, "{text}.0")
        }
    }
}

/// `Some(1.5)` or `None`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct OptionLit<T>(pub Option<T>);

impl<T: fmt::Display> fmt::Display for OptionLit<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.0 {
            Some(v) => write!(f, "Some({v})"),
            None => f.write_str("None"),
        }
    }
}

/// A string as a Rust string literal.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StrLit(pub String);

impl fmt::Display for StrLit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.0)
    }
}

/// ` + 40` / ` - 40`, nothing for zero: a term that reads naturally after an expression.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct SignedTerm(pub i128);

impl fmt::Display for SignedTerm {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            0 => Ok(()),
            v if v < 0 => write!(f, " - {}", v.unsigned_abs()),
            v => write!(f, " + {v}"),
        }
    }
}

/// A linear scaling `physical = raw * factor + offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Scaling {
    pub factor: f64,
    pub offset: f64,
}

impl Scaling {
    pub(crate) fn is_identity(&self) -> bool {
        self.factor == 1.0 && self.offset == 0.0
    }

    /// `operand * factor + offset`, leaving out identity steps.
    pub(crate) fn apply<T: fmt::Display>(self, operand: T) -> Scaled<T> {
        Scaled {
            scaling: self,
            operand,
        }
    }

    /// `(operand - offset) / factor`, leaving out identity steps.
    pub(crate) fn invert<T: fmt::Display>(self, operand: T) -> Unscaled<T> {
        Unscaled {
            scaling: self,
            operand,
        }
    }

    /// What the code [`Self::invert`] writes computes for `x`, step by step in `f64` as the
    /// generated code does (`v + 40.0` is the same IEEE operation as `v - -40.0`).
    pub(crate) fn invert_value(self, x: f64) -> f64 {
        let x = if self.offset != 0.0 {
            x - self.offset
        } else {
            x
        };
        if self.factor != 1.0 {
            x / self.factor
        } else {
            x
        }
    }

    /// `, physical = raw * 0.25 - 40` for docs (empty for identity scaling).
    pub(crate) fn doc(&self) -> String {
        if self.is_identity() {
            return String::new();
        }
        let factor = if self.factor == 1.0 {
            String::new()
        } else {
            format!(" * {}", FloatLit(self.factor))
        };
        let offset = match self.offset {
            0.0 => String::new(),
            o if o < 0.0 => format!(" - {}", FloatLit(-o)),
            o => format!(" + {}", FloatLit(o)),
        };
        format!(", physical = raw{factor}{offset}")
    }
}

/// See [`Scaling::apply`].
pub(crate) struct Scaled<T> {
    scaling: Scaling,
    operand: T,
}

impl<T: fmt::Display> fmt::Display for Scaled<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.operand)?;
        if self.scaling.factor != 1.0 {
            write!(f, " * {}", FloatLit(self.scaling.factor))?;
        }
        if self.scaling.offset != 0.0 {
            write!(f, " + {}", FloatLit(self.scaling.offset))?;
        }
        Ok(())
    }
}

/// See [`Scaling::invert`].
pub(crate) struct Unscaled<T> {
    scaling: Scaling,
    operand: T,
}

impl<T: fmt::Display> fmt::Display for Unscaled<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Scaling { factor, offset } = self.scaling;
        // `v + 40.0` rather than `v - -40.0`.
        let (sign, magnitude) = if offset < 0.0 {
            ('+', -offset)
        } else {
            ('-', offset)
        };
        match (factor != 1.0, offset != 0.0) {
            (false, false) => write!(f, "{}", self.operand),
            (false, true) => write!(f, "{} {sign} {}", self.operand, FloatLit(magnitude)),
            (true, false) => write!(f, "{} / {}", self.operand, FloatLit(factor)),
            (true, true) => write!(
                f,
                "({} {sign} {}) / {}",
                self.operand,
                FloatLit(magnitude),
                FloatLit(factor)
            ),
        }
    }
}

/// How an integer or float value widens to `f64` for scaling arithmetic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ToF64 {
    /// Lossless: `f64::from(x)`.
    From,
    /// 64-bit integers: `x as f64`.
    Cast,
    /// Already `f64`.
    Same,
}

impl ToF64 {
    pub(crate) fn of(self, operand: &'static str) -> Widened {
        Widened {
            kind: self,
            operand,
        }
    }
}

/// See [`ToF64::of`].
pub(crate) struct Widened {
    kind: ToF64,
    operand: &'static str,
}

impl fmt::Display for Widened {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            ToF64::From => write!(f, "f64::from({})", self.operand),
            ToF64::Cast => write!(f, "{} as f64", self.operand),
            ToF64::Same => f.write_str(self.operand),
        }
    }
}

/// The smallest signed type for integer scaling arithmetic over `lo..=hi` (raw and physical
/// ranges together): `i32` where it suffices, since wider math is multi-word on the Cortex-M7.
pub(crate) fn int_arith(lo: i128, hi: i128) -> &'static str {
    if lo >= i128::from(i32::MIN) && hi <= i128::from(i32::MAX) {
        "i32"
    } else if lo >= i128::from(i64::MIN) && hi <= i128::from(i64::MAX) {
        "i64"
    } else {
        "i128"
    }
}

/// Integer scaling `raw * factor + offset` in the type `arith`, exact for whole factors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct IntScaling {
    pub arith: &'static str,
    pub factor: i128,
    pub offset: i128,
}

impl IntScaling {
    pub(crate) fn offset_term(&self) -> SignedTerm {
        SignedTerm(self.offset)
    }

    pub(crate) fn minus_offset(&self) -> SignedTerm {
        SignedTerm(-self.offset)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float_literals_read_back_exactly() {
        for v in [0.0, 1.0, -40.0, 0.1, 1e-7, 1e300, f64::MIN_POSITIVE, 3.0e22] {
            let text = FloatLit(v).to_string();
            assert!(text.contains(['.', 'e']), "{text} is not a float literal");
            assert_eq!(text.parse::<f64>().ok(), Some(v));
        }
    }

    #[test]
    fn scaling_leaves_out_identity_steps() {
        let s = |factor, offset| Scaling { factor, offset };
        assert_eq!(s(1.0, 0.0).apply("raw").to_string(), "raw");
        assert_eq!(s(0.5, 0.0).apply("raw").to_string(), "raw * 0.5");
        assert_eq!(s(1.0, -40.0).apply("raw").to_string(), "raw + -40.0");
        assert_eq!(s(0.5, 2.0).invert("v").to_string(), "(v - 2.0) / 0.5");
        assert_eq!(s(1.0, 2.0).invert("v").to_string(), "v - 2.0");
        assert_eq!(s(1.0, -40.0).invert("v").to_string(), "v + 40.0");
        assert_eq!(s(0.5, -40.0).invert("v").to_string(), "(v + 40.0) / 0.5");
        assert_eq!(s(0.5, 0.0).invert("v").to_string(), "v / 0.5");
        assert_eq!(s(0.25, -40.0).doc(), ", physical = raw * 0.25 - 40.0");
    }

    #[test]
    fn signed_terms_read_naturally() {
        assert_eq!(SignedTerm(0).to_string(), "");
        assert_eq!(SignedTerm(-40).to_string(), " - 40");
        assert_eq!(SignedTerm(7).to_string(), " + 7");
    }

    #[test]
    fn arithmetic_type_is_the_narrowest_that_holds_the_range() {
        assert_eq!(int_arith(-5, 70_000), "i32");
        assert_eq!(int_arith(0, u32::MAX.into()), "i64");
        assert_eq!(int_arith(0, u64::MAX.into()), "i128");
    }
}
