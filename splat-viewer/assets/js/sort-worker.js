// The sort worker: created from a blob of sort.js and this file, so it needs no file of its own
// (a page opened from disk may not start a worker from a file).
let sortBackToFront = null;

self.onmessage = (event) => {
    const msg = event.data;
    if (msg.type === 'model') {
        sortBackToFront = createDepthSorter(msg.means);
        return;
    }
    if (msg.type === 'sort' && sortBackToFront) {
        const start = performance.now();
        const [r0, r1, r2, t] = msg.row;
        const order = sortBackToFront(r0, r1, r2, t, msg.near);
        self.postMessage(
            { type: 'sorted', id: msg.id, order, ms: performance.now() - start },
            [order.buffer],
        );
    }
};
