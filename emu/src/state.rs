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
    pub fn test<T: PartialOrd>(self, incoming: T, stored: T) -> bool {
        let _ = (incoming, stored);
        todo!()
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
        DepthState { test: false, func: CompareFunc::Less, write: false }
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
    /// The new stencil value; only bits in `write_mask` change.
    pub fn apply(self, value: u8, reference: u8, write_mask: u8) -> u8 {
        let _ = (value, reference, write_mask);
        todo!()
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
    /// 8-bit unsigned normalized; shader outputs are floats in [0,1].
    RGBA8,
}

impl Format {
    pub fn channels(self) -> usize {
        todo!()
    }
    /// Unsigned integer format (logic ops apply, blending does not).
    pub fn is_integer(self) -> bool {
        todo!()
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
    /// `src*1 + dst*0` on every channel with equation `eq` (MIN/MAX ignore the factors).
    pub fn equation(eq: BlendEquation) -> BlendState {
        let _ = eq;
        todo!()
    }
    /// Premultiplied-free "over" for front-to-back or back-to-front compositing helpers:
    /// colour `src*srcA + dst*(1-srcA)`, alpha `src + dst*(1-srcA)`.
    pub fn over() -> BlendState {
        todo!()
    }
    /// Blends `src` (shader output) onto `dst` (stored value).
    pub fn blend(&self, src: [f32; 4], dst: [f32; 4]) -> [f32; 4] {
        let _ = (src, dst);
        todo!()
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
    pub fn apply(self, src: u32, dst: u32) -> u32 {
        let _ = (src, dst);
        todo!()
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
    pub fn new(format: Format) -> TargetState {
        TargetState { format, blend: None, logic_op: None, write_mask: 0xf }
    }
    /// Combines a shader output with the stored texel, both raw 32-bit channel words (f32 bits
    /// for float formats, u32 for integer ones, f32 bits in [0,1] for RGBA8 as seen by the
    /// shader). Returns the new stored value (RGBA8 quantized to 8 bits, stored as the f32 of
    /// the quantized value k/255). Channels beyond the format's count are 0.
    pub fn combine(&self, src: [u32; 4], dst: [u32; 4]) -> [u32; 4] {
        let _ = (src, dst);
        todo!()
    }
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
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
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
        FragmentState { sample_mask: 0xff, ..Default::default() }
    }
}
