//! The command line's value parsers: how an option's text becomes its value (clap calls
//! them through `value_parser = ...`; an `Err` is printed by clap with the option's name).

/// `--thickness`: `NxP`, `NxP:BITS` or a fixed view depth ([`fragrace_kernels::merging::Thickness`]).
pub fn parse_thickness(s: &str) -> Result<fragrace_kernels::merging::Thickness, String> {
    s.parse()
        .map_err(|e: fragrace_kernels::merging::MergeParamError| e.to_string())
}

/// `--obj-step X,Y,Z` (and `--place`, `--look-at`, `--color`): three finite numbers.
pub fn parse_step(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{s}`: expected X,Y,Z (three numbers)"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("`{s}`: expected X,Y,Z (three finite numbers)")),
    }
}

/// `--binning`: `auto` or `always`.
pub fn parse_binning(s: &str) -> Result<fragrace_emu::Binning, String> {
    fragrace_emu::Binning::from_name(s).ok_or_else(|| format!("`{s}`: expected `auto` or `always`"))
}

/// `presort --method`: `cells` or `scan`.
pub fn parse_method(s: &str) -> Result<fragrace_kernels::presorted::Method, String> {
    use fragrace_kernels::presorted::Method;
    match s {
        "cells" => Ok(Method::Cells),
        "scan" => Ok(Method::Scan),
        _ => Err(format!("`{s}`: expected `cells` or `scan`")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_takes_three_finite_numbers_and_names_the_text_otherwise() {
        assert_eq!(parse_step("1, -2,3.5"), Ok([1.0, -2.0, 3.5]));
        for bad in ["1,2", "1,2,3,4", "a,b,c", "1,inf,2", "NaN,0,0"] {
            let e = parse_step(bad).expect_err(bad);
            assert!(e.starts_with(&format!("`{bad}`")), "{e}");
        }
    }

    #[test]
    fn binning_and_thickness_take_their_names() {
        assert_eq!(parse_binning("auto"), Ok(fragrace_emu::Binning::default()));
        assert!(parse_binning("never").unwrap_err().contains("`never`"));
        assert_eq!(
            parse_thickness("2xP"),
            Ok(fragrace_kernels::merging::Thickness::default())
        );
        assert!(parse_thickness("-1").is_err());
        assert_eq!(
            parse_method("scan"),
            Ok(fragrace_kernels::presorted::Method::Scan)
        );
        assert!(parse_method("lp").unwrap_err().contains("`lp`"));
    }
}
