#version 300 es
// One splat as a quad: splat-core's EWA projection (`splat_core::project`), its SH
// colour (`splat_core::sh`) and its constants (`splat_core::constants`), so the viewer draws
// what the CPU rasteriser draws. Frames as in splat-core: COLMAP camera (x right, y down,
// z forward), world→camera rotation and translation, pixel (0, 0)'s centre at (0.5, 0.5).
precision highp float;
precision highp int;
precision highp sampler2D;

// Six vertices (two triangles) per splat, no attributes: vertex v draws the splat at place
// v / 6 of the back-to-front order (from the sort worker), corner v % 6 of its quad. One plain
// draw rather than instancing: software renderers (SwiftShader) set every instance up anew,
// which cost about 0.1 ms a splat.
uniform highp usampler2D u_order;
const vec2 CORNERS[6] = vec2[6](vec2(-1.0, -1.0), vec2(1.0, -1.0), vec2(-1.0, 1.0),
    vec2(-1.0, 1.0), vec2(1.0, -1.0), vec2(1.0, 1.0));

// 4 texels per splat: (mean, opacity), (M col 0, dc.r), (M col 1, dc.g), (M col 2, dc.b) with
// M = R·S, so the world covariance is M·Mᵀ.
uniform sampler2D u_splats;
// SH bands 1..3, coefficient-major with the channel innermost, 4 floats a texel.
uniform sampler2D u_sh;
uniform int u_shTexels;
uniform int u_degree;
uniform mat3 u_rot;         // world → camera
uniform vec3 u_trans;
uniform vec3 u_center;      // camera centre in world
uniform vec2 u_focal;       // fx, fy (pixels)
uniform vec2 u_principal;   // cx, cy (pixels from the top-left corner)
uniform vec2 u_size;        // width, height (pixels)
uniform vec4 u_lim;         // the Jacobian's x/z clamp [x, y], y/z clamp [z, w]
uniform bool u_antialiased;

flat out vec4 v_color;      // colour, effective opacity
flat out vec3 v_conic;      // inverse 2D covariance (a, b, c)
out vec2 v_offset;          // pixel centre minus splat centre, pixels

// splat_core::constants
const float DILATION = 0.3;
const float MIN_ALPHA = 1.0 / 255.0;
const float NEAR_PLANE = 0.01;

// splat_core::sh (Inria's basis and signs)
const float SH_C0 = 0.2820948;
const float SH_C1 = 0.48860252;
const float SH_C2_0 = 1.0925484;
const float SH_C2_1 = -1.0925484;
const float SH_C2_2 = 0.31539157;
const float SH_C2_3 = -1.0925484;
const float SH_C2_4 = 0.5462742;
const float SH_C3_0 = -0.5900436;
const float SH_C3_1 = 2.8906114;
const float SH_C3_2 = -0.4570458;
const float SH_C3_3 = 0.37317634;
const float SH_C3_4 = -0.4570458;
const float SH_C3_5 = 1.4453057;
const float SH_C3_6 = -0.5900436;

ivec2 texel(sampler2D tex, int index) {
    int w = textureSize(tex, 0).x;
    return ivec2(index % w, index / w);
}

int splatIndex(int place) {
    int w = textureSize(u_order, 0).x;
    return int(texelFetch(u_order, ivec2(place % w, place / w), 0).r);
}

void cull() {
    // Outside the clip volume: the quad produces no fragment.
    gl_Position = vec4(0.0, 0.0, 2.0, 1.0);
}

// Σ_k basis_k(dir)·c_k for bands 1..degree (`splat_core::sh::eval` without the DC term).
vec3 shRest(int i, vec3 dir) {
    if (u_degree < 1) {
        return vec3(0.0);
    }
    vec4 s[12];
    int base = i * u_shTexels;
    for (int k = 0; k < 12; k++) {
        if (k < u_shTexels) {
            s[k] = texelFetch(u_sh, texel(u_sh, base + k), 0);
        }
    }
    float x = dir.x, y = dir.y, z = dir.z;
    vec3 c = -SH_C1 * y * s[0].xyz + SH_C1 * z * vec3(s[0].w, s[1].xy)
        - SH_C1 * x * vec3(s[1].zw, s[2].x);
    if (u_degree < 2) {
        return c;
    }
    float xx = x * x, yy = y * y, zz = z * z;
    c += SH_C2_0 * x * y * s[2].yzw
        + SH_C2_1 * y * z * s[3].xyz
        + SH_C2_2 * (2.0 * zz - xx - yy) * vec3(s[3].w, s[4].xy)
        + SH_C2_3 * x * z * vec3(s[4].zw, s[5].x)
        + SH_C2_4 * (xx - yy) * s[5].yzw;
    if (u_degree < 3) {
        return c;
    }
    c += SH_C3_0 * y * (3.0 * xx - yy) * s[6].xyz
        + SH_C3_1 * x * y * z * vec3(s[6].w, s[7].xy)
        + SH_C3_2 * y * (4.0 * zz - xx - yy) * vec3(s[7].zw, s[8].x)
        + SH_C3_3 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * s[8].yzw
        + SH_C3_4 * x * (4.0 * zz - xx - yy) * s[9].xyz
        + SH_C3_5 * z * (xx - yy) * vec3(s[9].w, s[10].xy)
        + SH_C3_6 * x * (xx - 3.0 * yy) * vec3(s[10].zw, s[11].x);
    return c;
}

void main() {
    int i = splatIndex(gl_VertexID / 6);
    vec2 corner = CORNERS[gl_VertexID % 6];
    vec4 t0 = texelFetch(u_splats, texel(u_splats, 4 * i), 0);
    vec4 t1 = texelFetch(u_splats, texel(u_splats, 4 * i + 1), 0);
    vec4 t2 = texelFetch(u_splats, texel(u_splats, 4 * i + 2), 0);
    vec4 t3 = texelFetch(u_splats, texel(u_splats, 4 * i + 3), 0);
    vec3 mean = t0.xyz;
    vec3 p = u_rot * mean + u_trans;
    if (p.z <= NEAR_PLANE || t0.w < MIN_ALPHA) {
        cull();
        return;
    }

    // EWA: T = J·W·M with J at the clamped x/z, y/z; Σ₂ = T·Tᵀ + 0.3·I.
    mat3 mc = u_rot * mat3(t1.xyz, t2.xyz, t3.xyz);
    float z = p.z;
    vec2 uRaw = p.xy / z;
    vec2 u = vec2(clamp(uRaw.x, u_lim.x, u_lim.y), clamp(uRaw.y, u_lim.z, u_lim.w));
    vec3 j0 = vec3(u_focal.x / z, 0.0, -u_focal.x * u.x / z);
    vec3 j1 = vec3(0.0, u_focal.y / z, -u_focal.y * u.y / z);
    mat3 mct = transpose(mc);
    vec3 r0 = mct * j0;
    vec3 r1 = mct * j1;
    float s00 = dot(r0, r0);
    float s01 = dot(r0, r1);
    float s11 = dot(r1, r1);
    // det(T·Tᵀ) as |r0 × r1|² (splat-core's `Cov2`): no cancellation for thin splats.
    vec3 minors = cross(r0, r1);
    float det0 = dot(minors, minors);
    float det = det0 + DILATION * (s00 + s11) + DILATION * DILATION;
    if (!(det > 0.0)) {
        cull();
        return;
    }
    float opacity = t0.w * (u_antialiased ? sqrt(det0 / det) : 1.0);
    if (opacity < MIN_ALPHA) {
        cull();
        return;
    }
    float a = s00 + DILATION;
    float b = s01;
    float c = s11 + DILATION;
    v_conic = vec3(c / det, -b / det, a / det);

    // The quad covers the ellipse where o·G ≥ 1/255: q ≤ 2·ln(255·o), with
    // `splat_core::projected::quad_bound`'s margin, along the covariance's eigenvectors.
    float qMax = 2.0 * log(255.0 * opacity) * 1.001 + 1e-3;
    vec2 centre = u_focal * uRaw + u_principal;
    // Off screen (its bounding box misses the image): culled before the SH, as splat-core culls
    // a splat that touches no tile.
    vec2 halfSize = sqrt(qMax * vec2(a, c));
    if (any(lessThan(centre + halfSize, vec2(0.0))) || any(greaterThan(centre - halfSize, u_size))) {
        cull();
        return;
    }
    float mid = 0.5 * (a + c);
    float l1 = mid + sqrt(max(0.25 * (a - c) * (a - c) + b * b, 0.0));
    float l2 = det / l1;
    vec2 axis = vec2(b, l1 - a);
    axis = dot(axis, axis) > 1e-20 ? normalize(axis) : vec2(1.0, 0.0);
    vec2 offset = corner.x * sqrt(qMax * l1) * axis
        + corner.y * sqrt(qMax * l2) * vec2(-axis.y, axis.x);
    vec2 pixel = centre + offset;
    gl_Position = vec4(2.0 * pixel.x / u_size.x - 1.0, 1.0 - 2.0 * pixel.y / u_size.y, 0.0, 1.0);
    v_offset = offset;

    // Colour towards the viewer: SH at normalize(mean − centre), + 0.5, clamped at 0.
    vec3 dir = normalize(mean - u_center);
    vec3 colour = SH_C0 * vec3(t1.w, t2.w, t3.w) + shRest(i, dir) + 0.5;
    v_color = vec4(max(colour, 0.0), opacity);
}
