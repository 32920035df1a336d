# Force ripple in a frequency band, from a forces.csv written by `dmplatform
# run` (columns t, fx, fy, fz, ...; one row per haptic tick).
#   awk -v LO=10 -v HI=100 [-v FROM=1] -f scripts/force_band.awk out/head_probe/forces.csv
# Over the rows with t >= FROM (s, default 1: after the first touch), the
# one-sided DFT at the bins k/T with LO <= k/T <= HI (Hz) of |F| − mean and of
# each of fx, fy, fz − mean, summed by Parseval into band RMS values; prints
# them with the strongest |F| bin; and the peak to peak of |F| minus its
# centred 0.2 s moving average (a high-pass that keeps what is above a few
# Hz, as a force trace plot shows ripple). Plain awk, O(rows × bins); about a second
# for 9 s at 1 kHz and a 90 Hz band.
BEGIN { FS = ","; if (FROM == "") FROM = 1; if (LO == "" || HI == "") { print "set -v LO=.. -v HI=.." > "/dev/stderr"; exit 2 } }
NR > 1 && $1 >= FROM {
  for (c = 1; c <= 3; c++) { g[c, m] = $(c + 1); sum[c] += $(c + 1) }
  g[0, m] = sqrt($2 * $2 + $3 * $3 + $4 * $4); sum[0] += g[0, m]
  if (m == 0) t0 = $1
  t1 = $1; m++
}
END {
  if (m < 2) { print "force_band: fewer than two rows after t = " FROM > "/dev/stderr"; exit 1 }
  T = m * (t1 - t0) / (m - 1)
  for (c = 0; c <= 3; c++) mean[c] = sum[c] / m
  best = 0
  for (k = int(LO * T + 0.999999); k <= HI * T; k++) {
    w = 6.283185307179586 * k / m
    for (c = 0; c <= 3; c++) {
      re = 0; im = 0
      for (j = 0; j < m; j++) { x = g[c, j] - mean[c]; re += x * cos(w * j); im += x * sin(w * j) }
      p = 2 * (re * re + im * im) / (m * m)
      if (c == 0) { e0 += p; if (p > best) { best = p; bf = k / T } } else ev += p
    }
  }
  W = int(0.1 / (T / m) + 0.5)
  for (j = 0; j < m; j++) cs[j + 1] = cs[j] + g[0, j]
  for (j = W; j < m - W; j++) {
    r = g[0, j] - (cs[j + W + 1] - cs[j - W]) / (2 * W + 1)
    if (j == W || r > hi) hi = r
    if (j == W || r < lo) lo = r
  }
  printf "%g-%g Hz: |F| rms %.4f N (strongest %.2f Hz, amplitude %.4f N), vector rms %.4f N; high-pass peak to peak %.3f N; mean |F| %.3f N over %.1f s\n",
         LO, HI, sqrt(e0), bf, sqrt(2 * best), sqrt(ev), hi - lo, mean[0], T
}
