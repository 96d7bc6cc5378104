// The viewer's camera: splat-core's pinhole (COLMAP axes: x right, y down, z forward; a
// world→camera rotation R, row-major here, and the camera centre c, so t = −R·c), and the orbit,
// pan and zoom moves about a target point in front of it.

const NEAR_PLANE = 0.01; // splat_core::constants::NEAR_PLANE
const FOV_CLAMP_MARGIN = 0.3; // splat_core::constants::FOV_CLAMP_MARGIN

function mat3Mul(a, b) {
    const o = new Array(9);
    for (let r = 0; r < 3; r++) {
        for (let c = 0; c < 3; c++) {
            o[3 * r + c] = a[3 * r] * b[c] + a[3 * r + 1] * b[3 + c] + a[3 * r + 2] * b[6 + c];
        }
    }
    return o;
}

function mat3Transpose(a) {
    return [a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8]];
}

function mat3Apply(a, v) {
    return [
        a[0] * v[0] + a[1] * v[1] + a[2] * v[2],
        a[3] * v[0] + a[4] * v[1] + a[5] * v[2],
        a[6] * v[0] + a[7] * v[1] + a[8] * v[2],
    ];
}

/// Rotation by `angle` about the unit `axis` (Rodrigues), row-major.
function axisAngle(axis, angle) {
    const [x, y, z] = axis;
    const c = Math.cos(angle);
    const s = Math.sin(angle);
    const t = 1 - c;
    return [
        t * x * x + c, t * x * y - s * z, t * x * z + s * y,
        t * x * y + s * z, t * y * y + c, t * y * z - s * x,
        t * x * z - s * y, t * y * z + s * x, t * z * z + c,
    ];
}

function normalize3(v) {
    const l = Math.hypot(v[0], v[1], v[2]);
    return l > 0 ? [v[0] / l, v[1] / l, v[2] / l] : [0, 0, 0];
}

class OrbitCamera {
    constructor() {
        this.rot = [1, 0, 0, 0, 1, 0, 0, 0, 1];
        this.center = [0, 0, -1];
        this.target = [0, 0, 0];
        this.up = [0, -1, 0];
    }

    /// The camera's axes in world coordinates: rows of R.
    right() { return [this.rot[0], this.rot[1], this.rot[2]]; }
    down() { return [this.rot[3], this.rot[4], this.rot[5]]; }
    forward() { return [this.rot[6], this.rot[7], this.rot[8]]; }

    distance() {
        const f = this.forward();
        const d = [0, 1, 2].map((k) => this.target[k] - this.center[k]);
        return Math.max(d[0] * f[0] + d[1] * f[1] + d[2] * f[2], 1e-6);
    }

    /// t = −R·c.
    translation() {
        const t = mat3Apply(this.rot, this.center);
        return [-t[0], -t[1], -t[2]];
    }

    /// Puts the camera at a view's pose; the target is where the view's axis passes closest to
    /// `focus`.
    setPose(rot, translation, focus) {
        this.rot = rot.slice();
        const c = mat3Apply(mat3Transpose(rot), translation);
        this.center = [-c[0], -c[1], -c[2]];
        const f = this.forward();
        const d = [0, 1, 2].map((k) => focus[k] - this.center[k]);
        const along = Math.max(d[0] * f[0] + d[1] * f[1] + d[2] * f[2], 1e-3);
        this.target = [0, 1, 2].map((k) => this.center[k] + f[k] * along);
    }

    /// Looks at `target` from `distance` along −`forward`, with `up` at the top of the image.
    lookAt(target, forward, distance) {
        const f = normalize3(forward);
        let r = normalize3(cross3(f, this.up));
        if (Math.hypot(...r) === 0) {
            r = normalize3(cross3(f, [1, 0, 0]));
        }
        const d = cross3(f, r);
        this.rot = [...r, ...d, ...f];
        this.target = target.slice();
        this.center = [0, 1, 2].map((k) => target[k] - f[k] * distance);
    }

    /// Turns the camera about the target: `yaw` about the world's up, `pitch` about the
    /// camera's right axis (radians). R' = R·Qᵀ, c' = target + Q·(c − target).
    orbit(yaw, pitch) {
        const q = mat3Mul(axisAngle(this.up, yaw), axisAngle(this.right(), pitch));
        this.rot = mat3Mul(this.rot, mat3Transpose(q));
        const rel = [0, 1, 2].map((k) => this.center[k] - this.target[k]);
        const moved = mat3Apply(q, rel);
        this.center = [0, 1, 2].map((k) => this.target[k] + moved[k]);
    }

    /// Moves camera and target along the image's axes (world units).
    pan(dx, dy) {
        const r = this.right();
        const d = this.down();
        for (let k = 0; k < 3; k++) {
            const m = dx * r[k] + dy * d[k];
            this.center[k] += m;
            this.target[k] += m;
        }
    }

    /// Multiplies the distance to the target by `factor`.
    zoom(factor) {
        const f = this.forward();
        const d = this.distance() * factor;
        this.center = [0, 1, 2].map((k) => this.target[k] - f[k] * d);
    }
}

function cross3(a, b) {
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
}

/// Intrinsics of a free view filling a width × height canvas with a vertical field of view.
function freeIntrinsics(width, height, fovYDegrees) {
    const f = height / (2 * Math.tan((fovYDegrees * Math.PI) / 360));
    return { width, height, fx: f, fy: f, cx: width / 2, cy: height / 2 };
}

/// The shader's Jacobian clamp for the intrinsics (`splat_core::project::ViewConsts`):
/// x/z within [−(cx/fx + 0.3·tx), (W − cx)/fx + 0.3·tx], tx = W/(2·fx), and the same for y.
function jacobianLimits(k) {
    const tx = (0.5 * k.width) / k.fx;
    const ty = (0.5 * k.height) / k.fy;
    return [
        -(k.cx / k.fx + FOV_CLAMP_MARGIN * tx),
        (k.width - k.cx) / k.fx + FOV_CLAMP_MARGIN * tx,
        -(k.cy / k.fy + FOV_CLAMP_MARGIN * ty),
        (k.height - k.cy) / k.fy + FOV_CLAMP_MARGIN * ty,
    ];
}
