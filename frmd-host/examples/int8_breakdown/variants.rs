//! The quantization-source combinations the breakdown runs, by label.
use crate::sim::Sources;

/// Every variant, in the order they are printed.
pub fn all() -> [(&'static str, Sources); 27] {
    let all = Sources {
        input: true,
        hidden_weights: true,
        output_weights: true,
        pre_activation: true,
        post_activation: true,
        clip: 0.0,
        fine: 1.0,
        pre_fine: 0.0,
        input_mode: 0,
    };
    [
        (
            "activations only, int16-like",
            Sources {
                pre_activation: true,
                post_activation: true,
                fine: 256.0,
                ..Default::default()
            },
        ),
        (
            "activations only, 2^-16 of int16",
            Sources {
                pre_activation: true,
                post_activation: true,
                fine: 16_777_216.0,
                ..Default::default()
            },
        ),
        (
            "all, two-plane input",
            Sources {
                input: false,
                input_mode: 3,
                ..all
            },
        ),
        (
            "clamp obs",
            Sources {
                input_mode: 4,
                ..Default::default()
            },
        ),
        (
            "clamp prev action",
            Sources {
                input_mode: 5,
                ..Default::default()
            },
        ),
        (
            "clamp rate",
            Sources {
                input_mode: 6,
                ..Default::default()
            },
        ),
        (
            "clamp trajectory",
            Sources {
                input_mode: 7,
                ..Default::default()
            },
        ),
        (
            "input clamp only",
            Sources {
                input_mode: 1,
                ..Default::default()
            },
        ),
        (
            "input rounding only",
            Sources {
                input_mode: 2,
                ..Default::default()
            },
        ),
        (
            "input two-plane-like",
            Sources {
                input_mode: 3,
                ..Default::default()
            },
        ),
        ("none (sanity)", Sources::default()),
        (
            "input",
            Sources {
                input: true,
                ..Default::default()
            },
        ),
        (
            "hidden weights",
            Sources {
                hidden_weights: true,
                ..Default::default()
            },
        ),
        (
            "output weights",
            Sources {
                output_weights: true,
                ..Default::default()
            },
        ),
        (
            "pre-activation (requant)",
            Sources {
                pre_activation: true,
                ..Default::default()
            },
        ),
        (
            "post-activation (LUT out)",
            Sources {
                post_activation: true,
                ..Default::default()
            },
        ),
        (
            "activations (pre+post)",
            Sources {
                pre_activation: true,
                post_activation: true,
                ..Default::default()
            },
        ),
        ("all", all),
        (
            "all but input (int16-like input)",
            Sources {
                input: false,
                ..all
            },
        ),
        (
            "all but input, pre clip 6",
            Sources {
                input: false,
                clip: 6.0,
                ..all
            },
        ),
        (
            "all but pre (wide LUT)",
            Sources {
                pre_activation: false,
                ..all
            },
        ),
        (
            "all, int16-like activations",
            Sources { fine: 256.0, ..all },
        ),
        (
            "int16 act + exact input",
            Sources {
                fine: 256.0,
                input: false,
                ..all
            },
        ),
        (
            "all, 10-bit pre-activation",
            Sources {
                pre_fine: 4.0,
                ..all
            },
        ),
        (
            "all, 12-bit pre-activation",
            Sources {
                pre_fine: 16.0,
                ..all
            },
        ),
        (
            "all, 16-bit pre-activation",
            Sources {
                pre_fine: 256.0,
                ..all
            },
        ),
        (
            "two-plane input, int16 act",
            Sources {
                input: false,
                input_mode: 3,
                fine: 256.0,
                ..all
            },
        ),
    ]
}
