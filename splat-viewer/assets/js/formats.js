// Model files → splats in the form the renderer uploads: SPZ (versions 2 and 3, gzip) and the
// Inria 3DGS PLY (binary little endian, float or double properties in any order). Decoding
// follows splat-core's readers (`splat_core::spz`, `splat_core::ply`), so a file renders the
// same here as in `transcode render`.
//
// A model is { count, shDegree, antialiased, means: Float32Array(3n), opacities: Float32Array(n)
// (activated), covFactors: Float32Array(9n) (M = R·S column by column, covariance M·Mᵀ),
// sh: Float32Array(n·K·3) (coefficient-major, channel innermost, K = (degree + 1)²) }, in
// splat-core's frame (COLMAP: x right, y down, z forward).

const SPZ_MAGIC = 0x5053474e; // "NGSP"
const SPZ_COLOR_SCALE = 0.15;

/// Decodes a model file's bytes (SPZ by its gzip signature, else PLY).
async function decodeModel(bytes) {
    if (bytes.length >= 2 && bytes[0] === 0x1f && bytes[1] === 0x8b) {
        return decodeSpz(await gunzip(bytes));
    }
    if (bytes.length >= 4 && String.fromCharCode(bytes[0], bytes[1], bytes[2]) === 'ply') {
        return decodePly(bytes);
    }
    throw new Error('not an SPZ (gzip) or PLY file');
}

async function gunzip(bytes) {
    if (typeof DecompressionStream === 'undefined') {
        throw new Error('this browser cannot decompress gzip (DecompressionStream); open a .ply');
    }
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('gzip'));
    return new Uint8Array(await new Response(stream).arrayBuffer());
}

function shCoefficients(degree) {
    return (degree + 1) * (degree + 1);
}

function emptyModel(count, shDegree) {
    return {
        count,
        shDegree,
        antialiased: false,
        means: new Float32Array(3 * count),
        opacities: new Float32Array(count),
        covFactors: new Float32Array(9 * count),
        sh: new Float32Array(count * shCoefficients(shDegree) * 3),
    };
}

function sigmoid(x) {
    return 1 / (1 + Math.exp(-x));
}

/// Stores splat i's covariance factor M = R(q/|q|)·diag(scale) (glam's `Mat3::from_quat`); a
/// zero or non-finite quaternion draws as the identity, as in `splat_core::normalize_quat`.
function setCovFactor(model, i, qw, qx, qy, qz, sx, sy, sz) {
    const m = Math.max(Math.abs(qw), Math.abs(qx), Math.abs(qy), Math.abs(qz));
    let w = 1, x = 0, y = 0, z = 0;
    if (Number.isFinite(m) && m > 0) {
        const n = Math.hypot(qw / m, qx / m, qy / m, qz / m);
        if (m * n > 1e-30) {
            w = qw / m / n; x = qx / m / n; y = qy / m / n; z = qz / m / n;
        }
    }
    const r = [
        1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y), // column 0
        2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x), // column 1
        2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y), // column 2
    ];
    const s = [sx, sy, sz];
    const o = 9 * i;
    for (let col = 0; col < 3; col++) {
        for (let row = 0; row < 3; row++) {
            model.covFactors[o + 3 * col + row] = r[3 * col + row] * s[col];
        }
    }
}

/// SPZ stores right-up-back; splat-core's frame is right-down-forward: a half turn about x
/// (`splat_core::frame::y_up_frame`), its own inverse. These are the SH signs it takes.
const HALF_TURN_X_SH_SIGN = [1, -1, -1, 1, -1, 1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1];

function decodeSpz(data) {
    const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
    if (data.length < 16 || view.getUint32(0, true) !== SPZ_MAGIC) {
        throw new Error('not an SPZ stream (no NGSP header)');
    }
    const version = view.getUint32(4, true);
    const n = view.getUint32(8, true);
    const degree = data[12];
    const fractionalBits = data[13];
    const flags = data[14];
    if (version < 2 || version > 3) {
        throw new Error(`SPZ version ${version}; versions 2 and 3 are read`);
    }
    if (degree > 3 || fractionalBits > 23) {
        throw new Error(`SPZ header with SH degree ${degree}, ${fractionalBits} fractional bits`);
    }
    const rotationBytes = version >= 3 ? 4 : 3;
    const k = shCoefficients(degree);
    const shPerSplat = (k - 1) * 3;
    const positions = 16;
    const alphas = positions + 9 * n;
    const colors = alphas + n;
    const scales = colors + 3 * n;
    const rotations = scales + 3 * n;
    const shStart = rotations + rotationBytes * n;
    if (data.length !== shStart + shPerSplat * n) {
        throw new Error(`SPZ body of ${data.length - 16} bytes where ${n} splats need ${shStart + shPerSplat * n - 16}`);
    }
    const model = emptyModel(n, degree);
    model.antialiased = (flags & 1) !== 0;
    const step = 1 / (1 << fractionalBits);
    const fixed = (o) => ((data[o] | (data[o + 1] << 8) | (data[o + 2] << 16)) << 8 >> 8) * step;
    const rest = new Float32Array(k * 3);
    for (let i = 0; i < n; i++) {
        const p = positions + 9 * i;
        // The half turn: (x, y, z) → (x, −y, −z).
        model.means[3 * i] = fixed(p);
        model.means[3 * i + 1] = -fixed(p + 3);
        model.means[3 * i + 2] = -fixed(p + 6);
        const a = Math.min(Math.max(data[alphas + i] / 255, 1e-6), 1 - 1e-6);
        model.opacities[i] = a;
        const s = scales + 3 * i;
        const sx = Math.exp(data[s] / 16 - 10);
        const sy = Math.exp(data[s + 1] / 16 - 10);
        const sz = Math.exp(data[s + 2] / 16 - 10);
        const q = rotationBytes === 4
            ? unpackQuaternion(view.getUint32(rotations + 4 * i, true))
            : unpackQuaternionV2(data, rotations + 3 * i);
        // Half turn of the quaternion: (w, x, y, z) → (w, x, −y, −z).
        setCovFactor(model, i, q[0], q[1], -q[2], -q[3], sx, sy, sz);
        const c = colors + 3 * i;
        for (let ch = 0; ch < 3; ch++) {
            rest[ch] = (data[c + ch] / 255 - 0.5) / SPZ_COLOR_SCALE;
        }
        const r = shStart + shPerSplat * i;
        for (let j = 0; j < shPerSplat; j++) {
            rest[3 + j] = (data[r + j] - 128) / 128;
        }
        const o = i * k * 3;
        for (let j = 0; j < k * 3; j++) {
            model.sh[o + j] = rest[j] * HALF_TURN_X_SH_SIGN[Math.floor(j / 3)];
        }
    }
    return model;
}

/// Version 3's smallest three: the largest component's index (x, y, z, w order) in the top two
/// bits, then the others as sign and 9-bit magnitude over [0, √½]; returns (w, x, y, z).
function unpackQuaternion(word) {
    const largest = word >>> 30;
    const c = [0, 0, 0, 0];
    let sum = 0;
    for (let i = 3; i >= 0; i--) {
        if (i !== largest) {
            const v = Math.SQRT1_2 * ((word & 511) / 511);
            c[i] = (word >>> 9) & 1 ? -v : v;
            sum += c[i] * c[i];
            word >>>= 10;
        }
    }
    c[largest] = Math.sqrt(Math.max(1 - sum, 0));
    return [c[3], c[0], c[1], c[2]];
}

function unpackQuaternionV2(data, o) {
    const x = data[o] / 127.5 - 1;
    const y = data[o + 1] / 127.5 - 1;
    const z = data[o + 2] / 127.5 - 1;
    return [Math.sqrt(Math.max(1 - x * x - y * y - z * z, 0)), x, y, z];
}

const PLY_TYPES = { float: 4, float32: 4, double: 8, float64: 8 };

function decodePly(bytes) {
    const headerEnd = findHeaderEnd(bytes);
    const header = new TextDecoder().decode(bytes.subarray(0, headerEnd)).split(/\r?\n/);
    if (!header.includes('format binary_little_endian 1.0')) {
        throw new Error('only binary little-endian PLY is read');
    }
    let count = -1;
    let current = null;
    let antialiased = false;
    const props = [];
    for (const line of header) {
        const w = line.trim().split(/\s+/);
        if (w[0] === 'comment') {
            antialiased = antialiasedComment(line.trim().slice('comment'.length), antialiased);
        } else if (w[0] === 'element') {
            // Only the vertex element is read, so it must be the first (Inria's layout).
            if (current === null && w[1] !== 'vertex') {
                throw new Error('the vertex element must come first');
            }
            if (current === null) {
                count = Number(w[2]);
            }
            current = w[1];
        } else if (w[0] === 'property' && current === 'vertex') {
            if (!(w[1] in PLY_TYPES)) {
                throw new Error(`vertex property ${w[w.length - 1]} of type ${w[1]}; float or double expected`);
            }
            props.push({ name: w[2], size: PLY_TYPES[w[1]] });
        }
    }
    if (!(count >= 0 && Number.isSafeInteger(count))) {
        throw new Error('no vertex element');
    }
    let stride = 0;
    const column = {};
    for (const p of props) {
        column[p.name] = { offset: stride, size: p.size };
        stride += p.size;
    }
    const need = ['x', 'y', 'z', 'f_dc_0', 'f_dc_1', 'f_dc_2', 'opacity', 'scale_0', 'scale_1',
        'scale_2', 'rot_0', 'rot_1', 'rot_2', 'rot_3'];
    for (const name of need) {
        if (!(name in column)) {
            throw new Error(`no ${name} property: not a 3DGS PLY`);
        }
    }
    let restCount = 0;
    while (`f_rest_${restCount}` in column) {
        restCount++;
    }
    const degree = { 0: 0, 9: 1, 24: 2, 45: 3 }[restCount];
    if (degree === undefined) {
        throw new Error(`${restCount} f_rest properties; degree 0–3 has 0, 9, 24 or 45`);
    }
    if (bytes.length < headerEnd + stride * count) {
        throw new Error(`the file ends before its ${count} vertices`);
    }
    const view = new DataView(bytes.buffer, bytes.byteOffset + headerEnd, stride * count);
    const model = emptyModel(count, degree);
    model.antialiased = antialiased;
    const k = shCoefficients(degree);
    const read = (row, name) => {
        const c = column[name];
        const o = row + c.offset;
        return c.size === 4 ? view.getFloat32(o, true) : view.getFloat64(o, true);
    };
    for (let i = 0; i < count; i++) {
        const row = i * stride;
        model.means[3 * i] = read(row, 'x');
        model.means[3 * i + 1] = read(row, 'y');
        model.means[3 * i + 2] = read(row, 'z');
        model.opacities[i] = sigmoid(read(row, 'opacity'));
        setCovFactor(model, i, read(row, 'rot_0'), read(row, 'rot_1'), read(row, 'rot_2'),
            read(row, 'rot_3'), Math.exp(read(row, 'scale_0')), Math.exp(read(row, 'scale_1')),
            Math.exp(read(row, 'scale_2')));
        const o = i * k * 3;
        for (let ch = 0; ch < 3; ch++) {
            model.sh[o + ch] = read(row, `f_dc_${ch}`);
            // f_rest is channel-major: channel ch's coefficients 1..K−1, then the next channel.
            for (let j = 1; j < k; j++) {
                model.sh[o + 3 * j + ch] = read(row, `f_rest_${ch * (k - 1) + j - 1}`);
            }
        }
    }
    return model;
}

/// What a PLY header comment says of the render mode (`splat_core::ply`'s reading): Brush's
/// `SplatRenderMode: mip | default`, Postshot's `antialiased 1 | 0` and
/// `postshot.anti_aliasing=1 | 0`, case-insensitive; any other comment leaves `before`.
function antialiasedComment(text, before) {
    const c = text.trim().toLowerCase();
    for (const [prefix, on] of [['splatrendermode:', 'mip'], ['antialiased ', '1'],
        ['postshot.anti_aliasing=', '1']]) {
        if (c.startsWith(prefix)) {
            return c.slice(prefix.length).trim() === on;
        }
    }
    return before;
}

function findHeaderEnd(bytes) {
    const marker = 'end_header';
    const limit = Math.min(bytes.length, 1 << 16);
    const text = new TextDecoder('latin1').decode(bytes.subarray(0, limit));
    const at = text.indexOf(marker);
    if (at < 0) {
        throw new Error('no end_header in the first 64 KiB');
    }
    let end = at + marker.length;
    if (text[end] === '\r') {
        end++;
    }
    if (text[end] !== '\n') {
        throw new Error('end_header is not followed by a newline');
    }
    return end + 1;
}
