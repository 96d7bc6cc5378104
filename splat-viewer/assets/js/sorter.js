// The main thread's side of the depth sort: one request in flight at a time, the latest camera
// kept for when it returns, so a moving camera is sorted as often as the worker can.

class Sorter {
    constructor(means, onSorted) {
        this.onSorted = onSorted;
        this.means = means;
        this.busy = false;
        this.pending = null;
        this.lastMs = 0;
        try {
            const source = `${VIEWER_SOURCES['sort.js']}\n${VIEWER_SOURCES['sort-worker.js']}`;
            const url = URL.createObjectURL(new Blob([source], { type: 'text/javascript' }));
            this.worker = new Worker(url);
            URL.revokeObjectURL(url);
            this.worker.onmessage = (e) => this.done(e.data);
            this.worker.onerror = (e) => {
                this.fallBack(`the sort worker failed (${e.message}); sorting on the page`);
            };
            this.worker.postMessage({ type: 'model', means });
        } catch (e) {
            this.worker = null;
            this.fallBack(`no sort worker (${e.message}); sorting on the page`);
        }
    }

    fallBack(why) {
        console.warn(why);
        if (this.worker) {
            this.worker.terminate();
            this.worker = null;
        }
        this.local = createDepthSorter(this.means);
        this.busy = false;
        if (this.pending) {
            const p = this.pending;
            this.pending = null;
            this.request(p.id, p.row);
        }
    }

    /// Asks for the order seen by a camera whose depth row is `row` ([r20, r21, r22, t2]).
    request(id, row) {
        if (this.busy) {
            this.pending = { id, row };
            return;
        }
        this.busy = true;
        if (this.worker) {
            this.worker.postMessage({ type: 'sort', id, row, near: NEAR_PLANE });
            return;
        }
        // Without a worker: the same sort, a tick later so the page stays responsive.
        setTimeout(() => {
            const start = performance.now();
            const order = this.local(row[0], row[1], row[2], row[3], NEAR_PLANE);
            this.done({ id, order, ms: performance.now() - start });
        }, 0);
    }

    done(result) {
        this.busy = false;
        this.lastMs = result.ms;
        this.onSorted(result);
        if (this.pending) {
            const p = this.pending;
            this.pending = null;
            this.request(p.id, p.row);
        }
    }
}
