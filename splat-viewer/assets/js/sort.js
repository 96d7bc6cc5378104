// The depth order of the splats, back to front, for one camera.
//
// splat-core composites each pixel front to back in the order of (camera-space depth, index),
// an order that is total. Drawing that order reversed with "over" blending gives the same
// image, so the sort here is exact rather than bucketed: depth is rounded to f32 as on the CPU,
// and since depths past the near plane are positive their IEEE bits order like their values; a
// stable LSD radix sort of those 32-bit keys in two 16-bit passes leaves ties in index order.

/// Reusable buffers of the sort, grown to the model's size.
function createDepthSorter(means) {
    const n = means.length / 3;
    const depth = new Float32Array(n);
    const keys = new Uint32Array(depth.buffer);
    const order = new Uint32Array(n);
    const keys2 = new Uint32Array(n);
    const order2 = new Uint32Array(n);
    const countLow = new Uint32Array(65536);
    const countHigh = new Uint32Array(65536);

    /// Returns the indices of the splats in front of the near plane, farthest first, for the
    /// camera whose depth is z = r0·x + r1·y + r2·z + t (its rotation's third row and
    /// translation's third component).
    return function sortBackToFront(r0, r1, r2, t, near) {
        let m = 0;
        for (let i = 0; i < n; i++) {
            const z = r0 * means[3 * i] + r1 * means[3 * i + 1] + r2 * means[3 * i + 2] + t;
            // Culled as in splat-core (z ≤ near plane); NaN fails the test too.
            if (z > near) {
                depth[m] = z;
                order[m] = i;
                m++;
            }
        }
        countLow.fill(0);
        countHigh.fill(0);
        for (let j = 0; j < m; j++) {
            const k = keys[j];
            countLow[k & 0xffff]++;
            countHigh[k >>> 16]++;
        }
        let sumLow = 0;
        let sumHigh = 0;
        for (let b = 0; b < 65536; b++) {
            const l = countLow[b];
            countLow[b] = sumLow;
            sumLow += l;
            const h = countHigh[b];
            countHigh[b] = sumHigh;
            sumHigh += h;
        }
        for (let j = 0; j < m; j++) {
            const k = keys[j];
            const at = countLow[k & 0xffff]++;
            keys2[at] = k;
            order2[at] = order[j];
        }
        const out = new Uint32Array(m);
        for (let j = 0; j < m; j++) {
            const k = keys2[j];
            // Ascending position, written from the end: farthest first.
            out[m - 1 - countHigh[k >>> 16]++] = order2[j];
        }
        return out;
    };
}
