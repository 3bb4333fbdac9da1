import jax, numpy as np, blurtrap as bt
bt.enable_x64()
def sim(k, gamma, dt, W, n, eps=0.0, seed=0):
    return np.asarray(bt.simulate(k, gamma, W, dt, n, key=jax.random.key(seed), method="exact_frames", tracking_std=eps)).reshape(-1)
gam = 6*np.pi*9.5e-4*0.765e-6; dt=1/1500; N=65536; T=N*dt
for ratio in [30, 100, 300, 1000, 3000]:
    tau = T/ratio; k = gam/tau
    res = {"whittle": [], "exact": []}
    for s in range(8):
        x = sim(k, gam, dt, dt, N, 2e-9, seed=s)
        rec = bt.Recording(x, frame_interval=dt, exposure=dt)
        for lk in res:
            try:
                r = bt.calibrate(rec, method="likelihood", likelihood=lk)
                res[lk].append(((r.k-k)/r.k_err, (r.gamma-gam)/r.gamma_err, r.k/k-1, r.gamma/gam-1))
            except Exception as e:
                res[lk].append((np.nan,)*4)
    for lk, v in res.items():
        v = np.array(v)
        print(f"T/tau={ratio} {lk}: mean z_k={np.nanmean(v[:,0]):+.2f} z_g={np.nanmean(v[:,1]):+.2f} rel k={np.nanmean(v[:,2]):+.3f} gamma={np.nanmean(v[:,3]):+.3f} nfail={np.isnan(v[:,0]).sum()}", flush=True)
