#version 300 es
// The Gaussian falloff of one splat at one pixel, premultiplied for back-to-front "over"
// blending (ONE, ONE_MINUS_SRC_ALPHA): splat-core's compositing read from the other end.
precision highp float;

flat in vec4 v_color;
flat in vec3 v_conic;
in vec2 v_offset;

out vec4 fragColor;

// splat_core::constants
const float MAX_ALPHA = 0.99;
const float MIN_ALPHA = 1.0 / 255.0;

void main() {
    vec2 d = v_offset;
    float power = -0.5 * (v_conic.x * d.x * d.x + v_conic.z * d.y * d.y) - v_conic.y * d.x * d.y;
    if (power > 0.0) {
        discard;
    }
    float alpha = min(MAX_ALPHA, v_color.a * exp(power));
    if (alpha < MIN_ALPHA) {
        discard;
    }
    fragColor = vec4(v_color.rgb * alpha, alpha);
}
