//! Value parsers shared by the command lines (`cargo xtask` and the benchmark commands;
//! feature `clap`): counts that must be at least one and image sides. `--device` is
//! [`crate::BackendKind`] itself, a `clap::ValueEnum` under this feature.

/// A count that must be at least 1 (`--steps`): 0 is refused with the reason.
pub fn at_least_one(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(format!("not a whole number: {e}")),
    }
}

/// An image side in pixels for generated scenes: 8 to 8192.
pub fn image_side(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(n) if (8..=8192).contains(&n) => Ok(n),
        Ok(n) => Err(format!("{n} pixels: must be between 8 and 8192")),
        Err(e) => Err(format!("not a whole number: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_sides_refuse_out_of_range_values() {
        assert_eq!(at_least_one("3"), Ok(3));
        assert!(at_least_one("0").unwrap_err().contains("at least 1"));
        assert!(at_least_one("-1").is_err());
        assert_eq!(image_side("24"), Ok(24));
        assert!(image_side("0").unwrap_err().contains("between 8 and 8192"));
        assert!(image_side("9000").is_err());
    }
}
