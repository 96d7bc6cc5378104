#version 300 es
// The splats' premultiplied colour over the background: rgb + T·background, T = 1 − alpha
// (splat-core's `resolve`).
precision highp float;

uniform sampler2D u_accum;
uniform vec3 u_background;

out vec4 fragColor;

void main() {
    vec4 s = texelFetch(u_accum, ivec2(gl_FragCoord.xy), 0);
    fragColor = vec4(s.rgb + (1.0 - s.a) * u_background, 1.0);
}
