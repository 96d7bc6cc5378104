// WebGL2 drawing: the splats' data textures, one quad per splat in the sort worker's order,
// blended back to front into a floating-point target, then put over the background.

const SH_TEXELS = [0, 3, 6, 12]; // texels of SH bands 1..degree per splat (9, 24, 45 floats)

class SplatRenderer {
    constructor(canvas, eightBit) {
        const gl = canvas.getContext('webgl2', {
            alpha: false,
            antialias: false,
            depth: false,
            stencil: false,
            premultipliedAlpha: false,
            preserveDrawingBuffer: false,
            powerPreference: 'high-performance',
        });
        if (!gl) {
            throw new Error('this browser has no WebGL2');
        }
        this.gl = gl;
        this.canvas = canvas;
        // Blending in 8 bits rounds at every splat; a half-float target keeps the sum of
        // hundreds of layers close to splat-core's f32 compositing.
        this.floatTarget = !eightBit && (!!gl.getExtension('EXT_color_buffer_float')
            || !!gl.getExtension('EXT_color_buffer_half_float'));
        this.splatProgram = program(gl, VIEWER_SOURCES['splat.vert'], VIEWER_SOURCES['splat.frag']);
        this.compositeProgram = program(gl, VIEWER_SOURCES['composite.vert'],
            VIEWER_SOURCES['composite.frag']);
        this.uniforms = uniformLocations(gl, this.splatProgram);
        this.compositeUniforms = uniformLocations(gl, this.compositeProgram);
        // The draw reads no attribute (splat.vert takes everything from textures).
        this.vao = gl.createVertexArray();
        this.instances = 0;
        this.model = null;
        this.target = null;
    }

    /// Uploads a decoded model (formats.js) as two float textures.
    setModel(model) {
        const gl = this.gl;
        const n = model.count;
        const k = (model.shDegree + 1) * (model.shDegree + 1);
        const maxWidth = Math.min(gl.getParameter(gl.MAX_TEXTURE_SIZE), 4096);
        const main = new Float32Array(16 * Math.max(n, 1));
        for (let i = 0; i < n; i++) {
            const o = 16 * i;
            main[o] = model.means[3 * i];
            main[o + 1] = model.means[3 * i + 1];
            main[o + 2] = model.means[3 * i + 2];
            const finite = Number.isFinite(main[o] + main[o + 1] + main[o + 2]);
            main[o + 3] = finite ? model.opacities[i] : 0;
            for (let col = 0; col < 3; col++) {
                for (let row = 0; row < 3; row++) {
                    main[o + 4 * (col + 1) + row] = model.covFactors[9 * i + 3 * col + row];
                }
                main[o + 4 * (col + 1) + 3] = model.sh[i * k * 3 + col];
            }
        }
        this.splatTexture = dataTexture(gl, this.splatTexture, main, 4 * Math.max(n, 1), maxWidth,
            gl.RGBA32F);
        const texels = SH_TEXELS[model.shDegree];
        const rest = new Float32Array(4 * Math.max(texels * n, 1));
        for (let i = 0; i < n && texels > 0; i++) {
            rest.set(model.sh.subarray((i * k + 1) * 3, (i + 1) * k * 3), 4 * texels * i);
        }
        // Half floats hold the higher bands to 11 bits, below the colour's 8-bit output.
        this.shTexture = dataTexture(gl, this.shTexture, rest, Math.max(texels * n, 1), maxWidth,
            gl.RGBA16F);
        this.model = { count: n, shDegree: model.shDegree, shTexels: texels,
            antialiased: model.antialiased };
        this.orderWidth = Math.min(Math.max(n, 1), maxWidth);
        this.orderRows = Math.ceil(Math.max(n, 1) / this.orderWidth);
        if (this.orderTexture) {
            gl.deleteTexture(this.orderTexture);
        }
        this.orderTexture = gl.createTexture();
        gl.bindTexture(gl.TEXTURE_2D, this.orderTexture);
        gl.texStorage2D(gl.TEXTURE_2D, 1, gl.R32UI, this.orderWidth, this.orderRows);
        setNearest(gl);
        this.instances = 0;
    }

    /// Sets the back-to-front order to draw (from the sort worker), as whole texture rows.
    setOrder(order) {
        const gl = this.gl;
        const rows = Math.ceil(order.length / this.orderWidth);
        if (rows > 0) {
            const padded = new Uint32Array(rows * this.orderWidth);
            padded.set(order);
            gl.bindTexture(gl.TEXTURE_2D, this.orderTexture);
            gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, this.orderWidth, rows, gl.RED_INTEGER,
                gl.UNSIGNED_INT, padded);
        }
        this.instances = order.length;
    }

    /// Draws the model seen by `camera` (OrbitCamera) with `intrinsics` over `background`.
    draw(camera, k, background, shDegree) {
        const gl = this.gl;
        const { width, height } = k;
        if (this.canvas.width !== width || this.canvas.height !== height) {
            this.canvas.width = width;
            this.canvas.height = height;
        }
        const target = this.floatTarget ? this.ensureTarget(width, height) : null;
        gl.bindFramebuffer(gl.FRAMEBUFFER, target ? target.framebuffer : null);
        gl.viewport(0, 0, width, height);
        if (target) {
            gl.clearColor(0, 0, 0, 0);
        } else {
            gl.clearColor(background[0], background[1], background[2], 1);
        }
        gl.clear(gl.COLOR_BUFFER_BIT);
        if (this.model && this.instances > 0) {
            const u = this.uniforms;
            gl.useProgram(this.splatProgram);
            gl.activeTexture(gl.TEXTURE0);
            gl.bindTexture(gl.TEXTURE_2D, this.splatTexture);
            gl.uniform1i(u.u_splats, 0);
            gl.activeTexture(gl.TEXTURE1);
            gl.bindTexture(gl.TEXTURE_2D, this.shTexture);
            gl.uniform1i(u.u_sh, 1);
            gl.activeTexture(gl.TEXTURE2);
            gl.bindTexture(gl.TEXTURE_2D, this.orderTexture);
            gl.uniform1i(u.u_order, 2);
            gl.uniform1i(u.u_shTexels, this.model.shTexels);
            gl.uniform1i(u.u_degree, Math.min(shDegree, this.model.shDegree));
            // GLSL matrices are column-major: R's columns are its transpose's rows.
            gl.uniformMatrix3fv(u.u_rot, false, mat3Transpose(camera.rot));
            gl.uniform3fv(u.u_trans, camera.translation());
            gl.uniform3fv(u.u_center, camera.center);
            gl.uniform2f(u.u_focal, k.fx, k.fy);
            gl.uniform2f(u.u_principal, k.cx, k.cy);
            gl.uniform2f(u.u_size, width, height);
            gl.uniform4fv(u.u_lim, jacobianLimits(k));
            gl.uniform1i(u.u_antialiased, this.model.antialiased ? 1 : 0);
            gl.enable(gl.BLEND);
            // Back to front, premultiplied: dst = src + (1 − src.a)·dst.
            gl.blendFunc(gl.ONE, gl.ONE_MINUS_SRC_ALPHA);
            gl.bindVertexArray(this.vao);
            gl.drawArrays(gl.TRIANGLES, 0, 6 * this.instances);
            gl.bindVertexArray(null);
            gl.disable(gl.BLEND);
        }
        if (target) {
            gl.bindFramebuffer(gl.FRAMEBUFFER, null);
            gl.viewport(0, 0, width, height);
            gl.useProgram(this.compositeProgram);
            gl.activeTexture(gl.TEXTURE0);
            gl.bindTexture(gl.TEXTURE_2D, target.texture);
            gl.uniform1i(this.compositeUniforms.u_accum, 0);
            gl.uniform3fv(this.compositeUniforms.u_background, background);
            gl.drawArrays(gl.TRIANGLES, 0, 3);
        }
    }

    /// Waits until the GPU has finished (for timing).
    finish() {
        const px = new Uint8Array(4);
        this.gl.readPixels(0, 0, 1, 1, this.gl.RGBA, this.gl.UNSIGNED_BYTE, px);
    }

    ensureTarget(width, height) {
        const gl = this.gl;
        if (this.target && this.target.width === width && this.target.height === height) {
            return this.target;
        }
        if (this.target) {
            gl.deleteTexture(this.target.texture);
            gl.deleteFramebuffer(this.target.framebuffer);
        }
        const texture = gl.createTexture();
        gl.bindTexture(gl.TEXTURE_2D, texture);
        gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA16F, width, height);
        setNearest(gl);
        const framebuffer = gl.createFramebuffer();
        gl.bindFramebuffer(gl.FRAMEBUFFER, framebuffer);
        gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, texture, 0);
        if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) {
            gl.bindFramebuffer(gl.FRAMEBUFFER, null);
            this.floatTarget = false;
            return null;
        }
        this.target = { width, height, texture, framebuffer };
        return this.target;
    }
}

function setNearest(gl) {
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
}

/// A texture of `texels` RGBA texels from `data`, `maxWidth` wide, rows filled in order.
function dataTexture(gl, old, data, texels, maxWidth, internalFormat) {
    if (old) {
        gl.deleteTexture(old);
    }
    const width = Math.min(texels, maxWidth);
    const height = Math.ceil(texels / width);
    if (height > gl.getParameter(gl.MAX_TEXTURE_SIZE)) {
        throw new Error(`the model needs a ${width}×${height} texture, more than this GPU allows`);
    }
    const padded = new Float32Array(4 * width * height);
    padded.set(data.subarray(0, Math.min(data.length, padded.length)));
    const texture = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, texture);
    gl.texImage2D(gl.TEXTURE_2D, 0, internalFormat, width, height, 0, gl.RGBA, gl.FLOAT, padded);
    setNearest(gl);
    return texture;
}

function program(gl, vertexSource, fragmentSource) {
    const p = gl.createProgram();
    for (const [type, source] of [[gl.VERTEX_SHADER, vertexSource],
        [gl.FRAGMENT_SHADER, fragmentSource]]) {
        const s = gl.createShader(type);
        gl.shaderSource(s, source);
        gl.compileShader(s);
        if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) {
            throw new Error(`shader does not compile: ${gl.getShaderInfoLog(s)}`);
        }
        gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) {
        throw new Error(`shaders do not link: ${gl.getProgramInfoLog(p)}`);
    }
    return p;
}

function uniformLocations(gl, p) {
    const out = {};
    const n = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < n; i++) {
        const name = gl.getActiveUniform(p, i).name;
        out[name] = gl.getUniformLocation(p, name);
    }
    return out;
}
