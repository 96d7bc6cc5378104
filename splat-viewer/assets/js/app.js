// The page: loads the scene (scene.js: model, cameras, pictures) and the model, wires the
// controls, draws on demand, and at a held-out camera lays the reference, the CPU render or the
// error map over the live render.
//
// URL parameters: view=NAME|INDEX (open at a camera), bg=black|white, sh=DEGREE,
// compare=reference|render|error, wipe=0..100 (percent of the width showing the live render),
// bench=FRAMES (orbit for that many frames and record the frame rate).
// For tests and scripts, window.splatViewer holds { ready, error, splats, view, sortMs, bench }:
// `ready` is true once the current camera's sort has been drawn.

const STATE = {
    ready: false,
    error: null,
    splats: 0,
    view: null,
    sortMs: [],
    frameMs: [],
    bench: null,
};
window.splatViewer = STATE;

const FREE_FOV_DEGREES = 50;
const ORBIT_RADIANS_PER_PIXEL = 0.005;

function el(tag, attrs, ...children) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
        if (k === 'class') {
            e.className = v;
        } else {
            e.setAttribute(k, v);
        }
    }
    for (const c of children) {
        e.append(c);
    }
    return e;
}

function loadScript(src) {
    return new Promise((resolve, reject) => {
        const s = el('script', { src });
        s.onload = resolve;
        s.onerror = () => reject(new Error(`cannot load ${src}`));
        document.head.append(s);
    });
}

function base64Bytes(text) {
    const bin = atob(text);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) {
        out[i] = bin.charCodeAt(i);
    }
    return out;
}

/// A robust centre and radius of the splats: per-axis medians and the 90th percentile distance,
/// over a sample.
function sceneBounds(means) {
    const n = means.length / 3;
    const step = Math.max(1, Math.floor(n / 20000));
    const axes = [[], [], []];
    for (let i = 0; i < n; i += step) {
        for (let k = 0; k < 3; k++) {
            if (Number.isFinite(means[3 * i + k])) {
                axes[k].push(means[3 * i + k]);
            }
        }
    }
    const median = (a) => (a.length ? a.sort((x, y) => x - y)[a.length >> 1] : 0);
    const centre = axes.map(median);
    const d = [];
    for (let i = 0; i < n; i += step) {
        const v = Math.hypot(means[3 * i] - centre[0], means[3 * i + 1] - centre[1],
            means[3 * i + 2] - centre[2]);
        if (Number.isFinite(v)) {
            d.push(v);
        }
    }
    d.sort((x, y) => x - y);
    return { centre, radius: d.length ? Math.max(d[Math.floor(0.9 * (d.length - 1))], 1e-3) : 1 };
}

/// The scene's up: the mean of the views' up directions (−y camera axes), else −y.
function sceneUp(views) {
    const up = [0, 0, 0];
    for (const v of views) {
        const r = v.camera.rotation;
        for (let k = 0; k < 3; k++) {
            up[k] -= r[1][k];
        }
    }
    const u = normalize3(up);
    return Math.hypot(...u) > 0 ? u : [0, -1, 0];
}

class Viewer {
    constructor(container) {
        this.container = container;
        this.base = container.dataset.base || './';
        this.scene = window.SPLAT_SCENE || { title: 'splats', model: null, views: [] };
        this.params = new URLSearchParams(window.location.search);
        this.background = this.params.get('bg') === 'white' ? [1, 1, 1] : [0, 0, 0];
        this.camera = new OrbitCamera();
        this.camera.up = sceneUp(this.scene.views);
        this.viewIndex = -1; // the held-out camera the intrinsics come from, −1 for free
        this.atView = false; // exactly at that camera's pose
        this.version = 0;
        this.sortedVersion = -1;
        this.dirty = false;
        this.framePending = false;
        this.lastFrame = 0;
        this.shDegree = 3;
        this.buildDom();
        this.renderer = new SplatRenderer(this.canvas, this.params.get('target') === '8bit');
        this.bindInput();
        new ResizeObserver(() => this.layout()).observe(this.stage);
    }

    buildDom() {
        const c = this.container;
        c.classList.add('sv-root');
        this.buttons = el('div', { class: 'sv-views' });
        const free = el('button', { type: 'button', title: 'A free camera filling the frame' }, 'free view');
        free.onclick = () => this.freeView();
        this.buttons.append(free);
        this.scene.views.forEach((v, i) => {
            const b = el('button', { type: 'button', title: `Jump to held-out camera ${v.name}` }, v.name);
            b.onclick = () => this.goToView(i);
            this.buttons.append(b);
        });
        this.bgSelect = el('select', { 'aria-label': 'background' },
            el('option', { value: 'black' }, 'black'), el('option', { value: 'white' }, 'white'));
        this.bgSelect.value = this.background[0] === 1 ? 'white' : 'black';
        this.bgSelect.onchange = () => {
            this.background = this.bgSelect.value === 'white' ? [1, 1, 1] : [0, 0, 0];
            this.redraw();
        };
        this.shSelect = el('select', { 'aria-label': 'SH degree' });
        this.shSelect.onchange = () => {
            this.shDegree = Number(this.shSelect.value);
            this.redraw();
        };
        this.fileInput = el('input', { type: 'file', accept: '.spz,.ply' });
        this.fileInput.onchange = () => {
            if (this.fileInput.files.length) {
                this.openFile(this.fileInput.files[0]);
            }
        };
        const bar = el('div', { class: 'sv-bar' }, this.buttons,
            el('label', {}, 'background ', this.bgSelect),
            el('label', {}, 'SH degree ', this.shSelect),
            el('label', { class: 'sv-open' }, 'open .spz / .ply ', this.fileInput));
        this.canvas = el('canvas', { class: 'sv-canvas', tabindex: '0' });
        this.overlay = el('img', { class: 'sv-overlay', alt: '' });
        this.overlay.hidden = true;
        this.divider = el('div', { class: 'sv-divider' });
        this.divider.hidden = true;
        this.message = el('div', { class: 'sv-message' }, 'loading…');
        this.stage = el('div', { class: 'sv-stage' }, this.canvas, this.overlay, this.divider,
            this.message);
        this.compareKind = el('select', { 'aria-label': 'compare with' },
            el('option', { value: 'none' }, 'nothing (live splats only)'),
            el('option', { value: 'reference' }, 'the reference view'),
            el('option', { value: 'render' }, 'the CPU render'),
            el('option', { value: 'error' }, 'the error map'));
        const kind = this.params.get('compare');
        this.compareKind.value = ['reference', 'render', 'error'].includes(kind) ? kind : 'none';
        this.wipe = el('input', { type: 'range', min: '0', max: '100', value: '50',
            'aria-label': 'share of the live render' });
        if (this.params.has('wipe')) {
            this.wipe.value = String(Number(this.params.get('wipe')) || 0);
        }
        this.compareKind.onchange = () => this.updateOverlay();
        this.wipe.oninput = () => this.updateOverlay();
        this.compare = el('div', { class: 'sv-compare' }, 'At this camera, compare the live render with ',
            this.compareKind, ' ', el('span', { class: 'sv-wipe' }, 'live ', this.wipe, ' picture'));
        this.status = el('div', { class: 'sv-status' });
        const help = el('div', { class: 'sv-help' },
            'drag: orbit · right-drag or shift-drag: pan · wheel or pinch: zoom · '
            + 'two fingers: pan · double-click: back to the camera');
        c.append(bar, this.stage, this.compare, this.status, help);
    }

    showMessage(text, isError) {
        this.message.textContent = text;
        this.message.hidden = !text;
        this.message.classList.toggle('sv-error', !!isError);
    }

    fail(error) {
        STATE.error = String(error && error.message ? error.message : error);
        this.showMessage(`Cannot show the model: ${STATE.error}`, true);
        console.error(error);
    }

    async start() {
        try {
            const bytes = await this.sceneModelBytes();
            if (!bytes) {
                return;
            }
            await this.setModel(await decodeModel(bytes));
        } catch (e) {
            this.fail(e);
        }
    }

    /// The scene's model: fetched over HTTP; from model.js (the bytes as base64) when the page
    /// was opened from disk, where browsers refuse fetch().
    async sceneModelBytes() {
        const m = this.scene.model;
        if (!m) {
            this.showMessage('No model in this scene: open an .spz or .ply file above.');
            return null;
        }
        if (window.location.protocol === 'file:') {
            try {
                await loadScript(this.base + m.embedded);
            } catch (e) {
                this.showMessage(`This page was opened from disk and the model is not embedded (too large): open ${this.base}${m.file} with the button above, or run \`transcode view\` on the output folder.`);
                return null;
            }
            return base64Bytes(window.SPLAT_MODEL_BASE64);
        }
        const response = await fetch(this.base + m.file);
        if (!response.ok) {
            throw new Error(`${m.file}: HTTP ${response.status}`);
        }
        return new Uint8Array(await response.arrayBuffer());
    }

    async openFile(file) {
        try {
            this.showMessage(`reading ${file.name}…`);
            await this.setModel(await decodeModel(new Uint8Array(await file.arrayBuffer())));
        } catch (e) {
            this.fail(e);
        }
    }

    async setModel(model) {
        STATE.ready = false;
        STATE.error = null;
        STATE.splats = model.count;
        this.model = model;
        this.bounds = sceneBounds(model.means);
        this.renderer.setModel(model);
        this.shDegree = model.shDegree;
        this.shSelect.replaceChildren(...Array.from({ length: model.shDegree + 1 },
            (_, d) => el('option', { value: String(d) }, String(d))));
        this.shSelect.value = String(model.shDegree);
        if (this.params.has('sh')) {
            this.shDegree = Math.min(Number(this.params.get('sh')) || 0, model.shDegree);
            this.shSelect.value = String(this.shDegree);
        }
        if (this.sorter && this.sorter.worker) {
            this.sorter.worker.terminate();
        }
        this.sorter = new Sorter(model.means, (r) => this.sorted(r));
        this.showMessage('');
        const wanted = this.params.get('view');
        const index = this.scene.views.findIndex((v, i) => v.name === wanted || String(i) === wanted);
        if (wanted !== null && index < 0) {
            throw new Error(`no camera named ${wanted}`);
        }
        if (index >= 0) {
            this.goToView(index);
        } else if (this.scene.views.length && wanted === null) {
            this.goToView(0);
        } else {
            this.freeView(true);
        }
        // The benchmark starts once the first sort is drawn (frame()).
        this.benchFrames = Number(this.params.get('bench')) || 0;
    }

    /// The intrinsics drawn with: the held-out camera's, or a free view filling the stage.
    intrinsics() {
        if (this.viewIndex >= 0) {
            return this.scene.views[this.viewIndex].camera;
        }
        const dpr = window.devicePixelRatio || 1;
        const w = Math.max(1, Math.round(this.stage.clientWidth * dpr));
        const h = Math.max(1, Math.round(this.stageHeight() * dpr));
        return freeIntrinsics(w, h, FREE_FOV_DEGREES);
    }

    stageHeight() {
        return Math.min(window.innerHeight * 0.75, this.stage.clientWidth * 0.625);
    }

    /// Sizes the canvas: a held-out camera at its own pixels (scaled down to fit), a free view
    /// filling the stage.
    layout() {
        const dpr = window.devicePixelRatio || 1;
        if (this.viewIndex >= 0) {
            const k = this.scene.views[this.viewIndex].camera;
            const scale = Math.min(1, this.stage.clientWidth / (k.width / dpr));
            this.cssSize = [(k.width / dpr) * scale, (k.height / dpr) * scale];
        } else {
            this.cssSize = [this.stage.clientWidth, this.stageHeight()];
        }
        for (const e of [this.canvas, this.overlay]) {
            e.style.width = `${this.cssSize[0]}px`;
            e.style.height = `${this.cssSize[1]}px`;
        }
        this.stage.style.height = `${this.cssSize[1]}px`;
        this.redraw();
    }

    goToView(i) {
        const v = this.scene.views[i];
        const r = v.camera.rotation;
        this.viewIndex = i;
        this.atView = true;
        STATE.view = v.name;
        this.camera.setPose([...r[0], ...r[1], ...r[2]], v.camera.translation,
            this.bounds ? this.bounds.centre : [0, 0, 0]);
        this.markButtons();
        this.layout();
        this.moved(true);
    }

    freeView(fit) {
        this.viewIndex = -1;
        this.atView = false;
        STATE.view = null;
        if (fit && this.bounds) {
            const d = this.bounds.radius / Math.tan((FREE_FOV_DEGREES * Math.PI) / 360) * 1.2;
            this.camera.lookAt(this.bounds.centre, [0, 0, 1], d);
        }
        this.markButtons();
        this.layout();
        this.moved(true);
    }

    markButtons() {
        [...this.buttons.children].forEach((b, j) => {
            b.classList.toggle('sv-active', j === this.viewIndex + 1);
        });
    }

    /// The camera moved: a new sort is asked for, the frame redrawn.
    moved(keepAtView) {
        if (!keepAtView && this.atView) {
            this.atView = false;
            STATE.view = null;
        }
        this.version++;
        STATE.ready = false;
        if (this.sorter) {
            const t = this.camera.translation();
            this.sorter.request(this.version, [this.camera.rot[6], this.camera.rot[7],
                this.camera.rot[8], t[2]]);
        }
        this.updateOverlay();
        this.redraw();
    }

    sorted(result) {
        STATE.sortMs.push(result.ms);
        if (STATE.sortMs.length > 200) {
            STATE.sortMs.shift();
        }
        this.renderer.setOrder(result.order);
        this.sortedVersion = result.id;
        this.redraw();
    }

    redraw() {
        this.dirty = true;
        if (!this.framePending) {
            this.framePending = true;
            requestAnimationFrame((t) => this.frame(t));
        }
    }

    frame(time) {
        this.framePending = false;
        if (!this.dirty || !this.model) {
            return;
        }
        this.dirty = false;
        try {
            this.renderer.draw(this.camera, this.intrinsics(), this.background, this.shDegree);
        } catch (e) {
            this.fail(e);
            return;
        }
        // Frames come on demand: only back-to-back frames (a moving camera) measure the rate.
        if (this.lastFrame && time - this.lastFrame < 500) {
            STATE.frameMs.push(time - this.lastFrame);
            if (STATE.frameMs.length > 60) {
                STATE.frameMs.shift();
            }
        }
        this.lastFrame = time;
        const ready = this.sortedVersion === this.version;
        STATE.ready = ready;
        this.container.dataset.ready = ready ? '1' : '0';
        this.updateStatus();
        if (ready && this.benchFrames > 0) {
            const frames = this.benchFrames;
            this.benchFrames = 0;
            this.benchmark(frames);
        }
    }

    updateStatus() {
        const k = this.intrinsics();
        const recent = STATE.frameMs.slice(-20);
        const mean = recent.length ? recent.reduce((a, b) => a + b, 0) / recent.length : 0;
        const parts = [`${this.model.count.toLocaleString('en')} splats`,
            `SH degree ${this.model.shDegree}`, `${k.width}×${k.height} px`,
            `sort ${this.sorter.lastMs.toFixed(1)} ms${this.sorter.worker ? ' (worker)' : ''}`];
        if (mean > 0) {
            parts.push(`${(1000 / mean).toFixed(0)} fps while moving`);
        }
        if (this.viewIndex >= 0) {
            const name = this.scene.views[this.viewIndex].name;
            parts.push(this.atView ? `at camera ${name}` : `moved from camera ${name}`);
        }
        this.status.textContent = parts.join(' · ');
    }

    updateOverlay() {
        const view = this.viewIndex >= 0 ? this.scene.views[this.viewIndex] : null;
        const kind = this.compareKind.value;
        const file = view && view.images ? view.images[kind] : null;
        this.compare.hidden = !(view && view.images);
        const live = Number(this.wipe.value);
        // All live (100): no picture and no divider at the edge.
        const show = this.atView && !!file && live < 100;
        this.overlay.hidden = !show;
        this.divider.hidden = !show || live <= 0;
        if (!show) {
            return;
        }
        const src = this.base + file;
        if (this.overlay.getAttribute('src') !== src) {
            this.overlay.src = src;
        }
        this.overlay.style.clipPath = `inset(0 0 0 ${live}%)`;
        this.divider.style.left = `${(live / 100) * this.cssSize[0]}px`;
        this.divider.style.height = `${this.cssSize[1]}px`;
    }

    bindInput() {
        const pointers = new Map();
        let last = null;
        const canvas = this.canvas;
        const pixelScale = () => this.intrinsics().height / this.cssSize[1];
        canvas.addEventListener('contextmenu', (e) => e.preventDefault());
        canvas.addEventListener('pointerdown', (e) => {
            canvas.setPointerCapture(e.pointerId);
            pointers.set(e.pointerId, { x: e.clientX, y: e.clientY, pan: e.button !== 0 || e.shiftKey });
            last = null;
        });
        const release = (e) => {
            pointers.delete(e.pointerId);
            last = null;
        };
        canvas.addEventListener('pointerup', release);
        canvas.addEventListener('pointercancel', release);
        canvas.addEventListener('pointermove', (e) => {
            const p = pointers.get(e.pointerId);
            if (!p) {
                return;
            }
            const dx = e.clientX - p.x;
            const dy = e.clientY - p.y;
            p.x = e.clientX;
            p.y = e.clientY;
            if (pointers.size === 1) {
                if (p.pan) {
                    this.panPixels(dx, dy, pixelScale());
                } else {
                    this.camera.orbit(-dx * ORBIT_RADIANS_PER_PIXEL, -dy * ORBIT_RADIANS_PER_PIXEL);
                }
                this.moved(false);
            } else if (pointers.size === 2) {
                // Pinch: the change of the fingers' distance zooms, their midpoint pans.
                const [a, b] = [...pointers.values()];
                const gap = Math.hypot(a.x - b.x, a.y - b.y);
                const mid = [(a.x + b.x) / 2, (a.y + b.y) / 2];
                if (last) {
                    if (gap > 0) {
                        this.camera.zoom(last.gap / gap);
                    }
                    this.panPixels(mid[0] - last.mid[0], mid[1] - last.mid[1], pixelScale());
                    this.moved(false);
                }
                last = { gap, mid };
            }
        });
        canvas.addEventListener('wheel', (e) => {
            e.preventDefault();
            const lines = e.deltaMode === 1 ? 16 : 1;
            this.camera.zoom(Math.exp(e.deltaY * lines * 0.0015));
            this.moved(false);
        }, { passive: false });
        canvas.addEventListener('dblclick', () => {
            if (this.viewIndex >= 0) {
                this.goToView(this.viewIndex);
            } else {
                this.freeView(true);
            }
        });
    }

    /// Moves the scene with the pointer: a pixel at the target's depth is distance / f.
    panPixels(dx, dy, scale) {
        const k = this.intrinsics();
        const perPixel = (this.camera.distance() / k.fy) * scale;
        this.camera.pan(-dx * perPixel, -dy * perPixel);
    }

    /// Orbits for `frames` frames, each drawn and waited for, and records the frame rate and
    /// the worker's sort times in window.splatViewer.bench.
    benchmark(frames) {
        const times = [];
        const drawMs = [];
        const sortsBefore = STATE.sortMs.length;
        let count = 0;
        let previous = 0;
        const step = (time) => {
            if (previous) {
                times.push(time - previous);
            }
            previous = time;
            if (count++ >= frames) {
                const total = times.reduce((a, b) => a + b, 0);
                const sorts = STATE.sortMs.slice(sortsBefore);
                STATE.bench = {
                    frames: times.length,
                    fps: (1000 * times.length) / total,
                    frameMsMean: total / times.length,
                    drawMsMean: drawMs.reduce((a, b) => a + b, 0) / drawMs.length,
                    sorts: sorts.length,
                    sortMsMean: sorts.reduce((a, b) => a + b, 0) / Math.max(sorts.length, 1),
                    sortMsMax: Math.max(0, ...sorts),
                    width: this.intrinsics().width,
                    height: this.intrinsics().height,
                };
                return;
            }
            this.camera.orbit((2 * Math.PI) / frames, 0);
            this.moved(false);
            this.dirty = true;
            const start = performance.now();
            this.frame(time);
            this.renderer.finish();
            drawMs.push(performance.now() - start);
            requestAnimationFrame(step);
        };
        requestAnimationFrame(step);
    }
}

function startViewers() {
    const title = document.querySelector('.sv-title');
    if (title && window.SPLAT_SCENE) {
        title.textContent = window.SPLAT_SCENE.title;
        document.title = window.SPLAT_SCENE.title;
    }
    for (const container of document.querySelectorAll('.splat-viewer')) {
        let viewer;
        try {
            viewer = new Viewer(container);
        } catch (e) {
            STATE.error = String(e.message || e);
            container.textContent = `Cannot start the viewer: ${STATE.error}`;
            console.error(e);
            continue;
        }
        viewer.start();
    }
}

if (document.readyState === 'loading') {
    document.addEventListener('DOMContentLoaded', startViewers);
} else {
    startViewers();
}
