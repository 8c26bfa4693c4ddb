//! Fixed-function per-fragment state: depth and stencil tests, render-target formats,
//! blending, logic ops and write masks, and the pure functions that apply them.
//!
//! This module knows nothing of shaders, memory or executors. Its functions are applied in
//! API order by the pipeline, so their results never depend on the order in which shader
//! invocations ran (as a GPU's ROP).

use serde::{Deserialize, Serialize};

/// Comparison of an incoming value with a stored one (`incoming FUNC stored`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum CompareFunc {
    Never,
    #[default]
    Less,
    Equal,
    LessEqual,
    Greater,
    NotEqual,
    GreaterEqual,
    Always,
}

impl CompareFunc {
    /// `incoming FUNC stored`, as GL's depth and stencil functions (`Less` passes when the
    /// incoming value is smaller). Unordered operands (NaN) fail every ordered comparison
    /// and pass `NotEqual`, as IEEE comparisons do.
    pub fn test<T: PartialOrd>(self, incoming: T, stored: T) -> bool {
        match self {
            CompareFunc::Never => false,
            CompareFunc::Less => incoming < stored,
            CompareFunc::Equal => incoming == stored,
            CompareFunc::LessEqual => incoming <= stored,
            CompareFunc::Greater => incoming > stored,
            CompareFunc::NotEqual => incoming != stored,
            CompareFunc::GreaterEqual => incoming >= stored,
            CompareFunc::Always => true,
        }
    }
}

/// Depth test state.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DepthState {
    pub test: bool,
    pub func: CompareFunc,
    pub write: bool,
}

impl Default for DepthState {
    /// Test and write disabled (every fragment passes).
    fn default() -> Self {
        DepthState {
            test: false,
            func: CompareFunc::Less,
            write: false,
        }
    }
}

/// Stencil operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum StencilOp {
    #[default]
    Keep,
    Zero,
    Replace,
    IncrClamp,
    DecrClamp,
    Invert,
    IncrWrap,
    DecrWrap,
}

impl StencilOp {
    /// The new stencil value; only bits in `write_mask` change
    /// (`(value & !write_mask) | (new & write_mask)`, as GL's stencil write mask).
    ///
    /// The clamped ops saturate at 0 and 255, the wrapping ones wrap modulo 256 (the
    /// 8-bit wrap that stencil-routing algorithms must account for).
    pub fn apply(self, value: u8, reference: u8, write_mask: u8) -> u8 {
        let new = match self {
            StencilOp::Keep => value,
            StencilOp::Zero => 0,
            StencilOp::Replace => reference,
            StencilOp::IncrClamp => value.saturating_add(1),
            StencilOp::DecrClamp => value.saturating_sub(1),
            StencilOp::Invert => !value,
            StencilOp::IncrWrap => value.wrapping_add(1),
            StencilOp::DecrWrap => value.wrapping_sub(1),
        };
        (value & !write_mask) | (new & write_mask)
    }
}

/// Stencil state of one face.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct StencilFace {
    pub func: CompareFunc,
    pub fail_op: StencilOp,
    pub depth_fail_op: StencilOp,
    pub pass_op: StencilOp,
    pub reference: u8,
    pub read_mask: u8,
    pub write_mask: u8,
}

impl Default for StencilFace {
    fn default() -> Self {
        StencilFace {
            func: CompareFunc::Always,
            fail_op: StencilOp::Keep,
            depth_fail_op: StencilOp::Keep,
            pass_op: StencilOp::Keep,
            reference: 0,
            read_mask: 0xff,
            write_mask: 0xff,
        }
    }
}

/// Stencil state, front and back faces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct StencilState {
    pub enabled: bool,
    pub front: StencilFace,
    pub back: StencilFace,
}

/// Render-target formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Format {
    R32F,
    RG32F,
    RGBA32F,
    R32UI,
    RGBA32UI,
    /// 8-bit unsigned normalized; shader outputs are floats, clamped to `[0, 1]` and stored
    /// quantized to `k / 255` (as f32 bits, so readers see exactly what an 8-bit target holds).
    RGBA8,
}

impl Format {
    /// Number of stored channels; the remaining channels of a texel's `[u32; 4]` are 0.
    pub fn channels(self) -> usize {
        match self {
            Format::R32F | Format::R32UI => 1,
            Format::RG32F => 2,
            Format::RGBA32F | Format::RGBA32UI | Format::RGBA8 => 4,
        }
    }
    /// Unsigned integer format (logic ops apply, blending does not).
    pub fn is_integer(self) -> bool {
        matches!(self, Format::R32UI | Format::RGBA32UI)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum BlendEquation {
    #[default]
    Add,
    Subtract,
    ReverseSubtract,
    Min,
    Max,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum BlendFactor {
    Zero,
    One,
    SrcColor,
    OneMinusSrcColor,
    DstColor,
    OneMinusDstColor,
    SrcAlpha,
    OneMinusSrcAlpha,
    DstAlpha,
    OneMinusDstAlpha,
    ConstantColor,
    OneMinusConstantColor,
    ConstantAlpha,
    OneMinusConstantAlpha,
    SrcAlphaSaturate,
}

/// Blending of one render target (separate colour and alpha equations and factors).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlendState {
    pub color_eq: BlendEquation,
    pub alpha_eq: BlendEquation,
    pub src_color: BlendFactor,
    pub dst_color: BlendFactor,
    pub src_alpha: BlendFactor,
    pub dst_alpha: BlendFactor,
    pub constant: [f32; 4],
}

impl BlendState {
    /// Equation `eq` on every channel with both factors `One`: `Add` is `src + dst`,
    /// `Subtract` is `src - dst`, `ReverseSubtract` is `dst - src`, and `Min`/`Max` ignore
    /// the factors (as in GL). Factors of one make `equation(Add)` plain additive blending,
    /// the common use in multi-fragment algorithms (counting fragments, accumulating
    /// weighted sums); factors `One`/`Zero` would make `Add` a plain copy, for which no
    /// blending is needed at all.
    pub fn equation(eq: BlendEquation) -> BlendState {
        BlendState {
            color_eq: eq,
            alpha_eq: eq,
            src_color: BlendFactor::One,
            dst_color: BlendFactor::One,
            src_alpha: BlendFactor::One,
            dst_alpha: BlendFactor::One,
            constant: [0.0; 4],
        }
    }
    /// Non-premultiplied "over" for back-to-front compositing:
    /// colour `src*srcA + dst*(1-srcA)`, alpha `src + dst*(1-srcA)` (so the stored alpha is
    /// the accumulated coverage).
    pub fn over() -> BlendState {
        BlendState {
            color_eq: BlendEquation::Add,
            alpha_eq: BlendEquation::Add,
            src_color: BlendFactor::SrcAlpha,
            dst_color: BlendFactor::OneMinusSrcAlpha,
            src_alpha: BlendFactor::One,
            dst_alpha: BlendFactor::OneMinusSrcAlpha,
            constant: [0.0; 4],
        }
    }
    /// Blends `src` (shader output) onto `dst` (stored value), GL's equations: channels
    /// 0..3 use the colour equation and factors, channel 3 the alpha ones. A colour factor
    /// on the alpha channel takes that colour's alpha (`SrcColor` is `As` there), and
    /// `SrcAlphaSaturate` is `min(As, 1 - Ad)` on colour and 1 on alpha. No clamping is done
    /// here (float targets do not clamp); [`TargetState::combine`] clamps normalized targets.
    pub fn blend(&self, src: [f32; 4], dst: [f32; 4]) -> [f32; 4] {
        let mut out = [0.0; 4];
        for (c, o) in out.iter_mut().enumerate() {
            let (eq, sf, df) = if c < 3 {
                (self.color_eq, self.src_color, self.dst_color)
            } else {
                (self.alpha_eq, self.src_alpha, self.dst_alpha)
            };
            let s = src[c];
            let d = dst[c];
            *o = match eq {
                BlendEquation::Add => {
                    s * self.factor(sf, c, src, dst) + d * self.factor(df, c, src, dst)
                }
                BlendEquation::Subtract => {
                    s * self.factor(sf, c, src, dst) - d * self.factor(df, c, src, dst)
                }
                BlendEquation::ReverseSubtract => {
                    d * self.factor(df, c, src, dst) - s * self.factor(sf, c, src, dst)
                }
                BlendEquation::Min => s.min(d),
                BlendEquation::Max => s.max(d),
            };
        }
        out
    }

    /// The value of factor `f` for channel `c` (GL's table).
    fn factor(&self, f: BlendFactor, c: usize, src: [f32; 4], dst: [f32; 4]) -> f32 {
        let k = self.constant;
        match f {
            BlendFactor::Zero => 0.0,
            BlendFactor::One => 1.0,
            BlendFactor::SrcColor => src[c],
            BlendFactor::OneMinusSrcColor => 1.0 - src[c],
            BlendFactor::DstColor => dst[c],
            BlendFactor::OneMinusDstColor => 1.0 - dst[c],
            BlendFactor::SrcAlpha => src[3],
            BlendFactor::OneMinusSrcAlpha => 1.0 - src[3],
            BlendFactor::DstAlpha => dst[3],
            BlendFactor::OneMinusDstAlpha => 1.0 - dst[3],
            BlendFactor::ConstantColor => k[c],
            BlendFactor::OneMinusConstantColor => 1.0 - k[c],
            BlendFactor::ConstantAlpha => k[3],
            BlendFactor::OneMinusConstantAlpha => 1.0 - k[3],
            BlendFactor::SrcAlphaSaturate => {
                if c < 3 {
                    src[3].min(1.0 - dst[3])
                } else {
                    1.0
                }
            }
        }
    }
}

/// Logic operation on unsigned-integer targets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum LogicOp {
    Copy,
    Or,
    And,
    Xor,
}

impl LogicOp {
    /// `src OP dst` bitwise (`Copy` is `src`).
    pub fn apply(self, src: u32, dst: u32) -> u32 {
        match self {
            LogicOp::Copy => src,
            LogicOp::Or => src | dst,
            LogicOp::And => src & dst,
            LogicOp::Xor => src ^ dst,
        }
    }
}

/// State of one render target binding.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TargetState {
    pub format: Format,
    /// Blending (float and RGBA8 targets only).
    pub blend: Option<BlendState>,
    /// Logic op (integer targets only).
    pub logic_op: Option<LogicOp>,
    /// Bit c set = channel c written.
    pub write_mask: u8,
}

impl TargetState {
    /// A plain write of every channel of a four-channel 32-bit format (a resolve's target):
    /// [`TargetState::combine`] gives the output's bits, whatever the stored texel, as its
    /// general case computes them.
    #[inline]
    pub fn plain_write(&self) -> bool {
        self.format.channels() == 4
            && self.write_mask & 0xf == 0xf
            && self.blend.is_none()
            && self.logic_op.is_none()
            && self.format != Format::RGBA8
    }

    pub fn new(format: Format) -> TargetState {
        TargetState {
            format,
            blend: None,
            logic_op: None,
            write_mask: 0xf,
        }
    }
    /// Combines a shader output with the stored texel, both raw 32-bit channel words (f32 bits
    /// for float formats and RGBA8, whose shader output may be any float, u32 for integer
    /// ones). Returns the new stored value (RGBA8 quantized to 8 bits, stored as the f32 of
    /// the quantized value k/255). Channels beyond the format's count are 0.
    ///
    /// * Float formats: `blend` if set, else a copy of the bits. The destination's missing
    ///   channels read as `(0, 0, 0, 1)` (GL: a target without alpha has destination alpha
    ///   1), while the source keeps all four shader channels (source alpha factors use the
    ///   shader's alpha even on an `R32F` target).
    /// * `RGBA8`: the source is clamped to `[0, 1]` (NaN to 0), blended in float with the stored
    ///   value, clamped again and rounded to the nearest `k/255`; storing `k as f32 / 255.0`
    ///   exactly lets later reads see the quantized value, as an 8-bit target would.
    /// * Integer formats: `logic_op` if set, else a copy; `blend` is ignored (GL).
    ///
    /// Then channel `c` takes the new value only if bit `c` of `write_mask` is set; other
    /// channels keep `dst`.
    #[inline]
    pub fn combine(&self, src: [u32; 4], dst: [u32; 4]) -> [u32; 4] {
        let n = self.format.channels();
        if self.plain_write() {
            return src;
        }
        let new: [u32; 4] = match self.format {
            Format::R32UI | Format::RGBA32UI => match self.logic_op {
                Some(op) => std::array::from_fn(|c| op.apply(src[c], dst[c])),
                None => src,
            },
            Format::RGBA8 => {
                let s = src.map(|w| clamp01(f32::from_bits(w)));
                let v = match &self.blend {
                    Some(b) => b.blend(s, dst.map(f32::from_bits)),
                    None => s,
                };
                v.map(|x| quantize_unorm8(x).to_bits())
            }
            Format::R32F | Format::RG32F | Format::RGBA32F => match &self.blend {
                Some(b) => {
                    let d: [f32; 4] = std::array::from_fn(|c| {
                        if c < n {
                            f32::from_bits(dst[c])
                        } else if c == 3 {
                            1.0
                        } else {
                            0.0
                        }
                    });
                    b.blend(src.map(f32::from_bits), d).map(f32::to_bits)
                }
                None => src,
            },
        };
        std::array::from_fn(|c| {
            if c >= n {
                0
            } else if self.write_mask & (1 << c) != 0 {
                new[c]
            } else {
                dst[c]
            }
        })
    }
}

/// Clamps to `[0, 1]`, NaN to 0 (the conversion of a float to a normalized value).
fn clamp01(x: f32) -> f32 {
    if x.is_nan() {
        0.0
    } else {
        x.clamp(0.0, 1.0)
    }
}

/// Rounds `x` (clamped to `[0, 1]`) to the nearest multiple of 1/255 and returns `k / 255.0`,
/// the float an 8-bit normalized target reads back as.
pub fn quantize_unorm8(x: f32) -> f32 {
    let k = (clamp01(x) * 255.0).round();
    k / 255.0
}

/// When the depth/stencil test runs relative to the shader.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum EarlyTests {
    /// Early when the kernel neither discards nor writes depth, late otherwise.
    #[default]
    Auto,
    /// Always early (GLSL `early_fragment_tests`): a discard no longer undoes the depth write.
    ForceEarly,
    ForceLate,
}

/// All fixed-function per-fragment state of a pass.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FragmentState {
    pub depth: DepthState,
    pub stencil: StencilState,
    pub early: EarlyTests,
    /// Up to 8 render targets.
    pub targets: Vec<TargetState>,
    /// Sample mask ANDed with coverage (bit s = sample s).
    pub sample_mask: u8,
}

impl FragmentState {
    /// No targets, no tests, all samples.
    pub fn new() -> FragmentState {
        FragmentState {
            depth: DepthState::default(),
            stencil: StencilState::default(),
            early: EarlyTests::default(),
            targets: Vec::new(),
            sample_mask: 0xff,
        }
    }
}

impl Default for FragmentState {
    /// Same as [`FragmentState::new`]: a derived default would have a sample mask of 0,
    /// which silently discards every sample.
    fn default() -> Self {
        FragmentState::new()
    }
}
