// Session 14's microbenchmark of the GPU solver's memory access (BENCHMARKS.md, 2026-12-05):
// a 656-byte constraint a thread (the layout of ContactConstraint) against 32 constraints'
// 16-byte words interleaved, over the batch sizes of the settled 100k and 500k piles and 3k.
// On the GPU machine: nvcc -O3 -arch=sm_90 -o /tmp/layout docs/bench/h200-s14-solver-layout.cu && /tmp/layout 0
// (0: 100k pile, 1: 500k pile, 2: falling-boxes 3k). An approximation of the solve sweep:
// the same loads and stores, fewer operations than solver.wgsl.
#include <cstdio>
#include <cstdlib>
#include <vector>
#include <algorithm>
#include <random>
#include <cuda_runtime.h>

#define SLOTS 41
#define HEADER 5
#define POINT 9

template <bool TILED>
__device__ __forceinline__ size_t addr(unsigned i, unsigned s) {
  if (TILED) return ((size_t)(i >> 5) * SLOTS + s) * 32 + (i & 31);
  return (size_t)i * SLOTS + s;
}

struct Body { float4 v, w, dp, dq; };

__device__ float3 f3(float4 a) { return make_float3(a.x, a.y, a.z); }
__device__ float dot3(float3 a, float3 b) { return a.x*b.x + a.y*b.y + a.z*b.z; }
__device__ float3 cross3(float3 a, float3 b) { return make_float3(a.y*b.z-a.z*b.y, a.z*b.x-a.x*b.z, a.x*b.y-a.y*b.x); }
__device__ float3 add3(float3 a, float3 b) { return make_float3(a.x+b.x, a.y+b.y, a.z+b.z); }
__device__ float3 mul3(float3 a, float s) { return make_float3(a.x*s, a.y*s, a.z*s); }

template <bool TILED>
__global__ void solve(const unsigned* offsets, int batch, float4* c, Body* bodies) {
  unsigned i = offsets[batch] + blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= offsets[batch + 1]) return;
  uint4 h0 = reinterpret_cast<uint4*>(c)[addr<TILED>(i, 0)];
  float4 h1 = c[addr<TILED>(i, 1)];
  float4 h2 = c[addr<TILED>(i, 2)];
  float4 h3 = c[addr<TILED>(i, 3)];
  float4 h4 = c[addr<TILED>(i, 4)];
  unsigned count = h0.w;
  float4 p[4][POINT];
#pragma unroll
  for (int k = 0; k < 4; k++) {
    if (k < count) {
#pragma unroll
      for (int s = 0; s < POINT; s++) p[k][s] = c[addr<TILED>(i, HEADER + k * POINT + s)];
    } else {
#pragma unroll
      for (int s = 0; s < POINT; s++) p[k][s] = make_float4(0, 0, 0, 0);
    }
  }
  Body a = bodies[h0.x], b = bodies[h0.y];
  float3 n = f3(h1);
  float3 va = f3(a.v), wa = f3(a.w), vb = f3(b.v), wb = f3(b.w);
  // normal rows then friction rows, roughly the real flop count
#pragma unroll
  for (int k = 0; k < 4; k++) {
    if (k < count) {
      float3 ra = f3(p[k][6]), rb = f3(p[k][7]);
      float3 moved = add3(f3(a.dp), cross3(f3(a.dq), ra));
      float sep = dot3(n, moved) + p[k][6].w;
      float vel = dot3(n, add3(va, mul3(vb, -1.f))) + dot3(cross3(ra, n), wa) - dot3(cross3(rb, n), wb);
      float imp = -p[k][0].w * (vel + sep * 0.1f);
      float tot = fmaxf(p[k][1].w + imp, 0.f);
      float d = tot - p[k][1].w;
      p[k][1].w = tot;
      p[k][8].y = fmaxf(p[k][8].y, tot);
      va = add3(va, mul3(n, d * h3.w)); wa = add3(wa, mul3(f3(p[k][0]), d));
      vb = add3(vb, mul3(n, -d * h4.x)); wb = add3(wb, mul3(f3(p[k][1]), -d));
    }
  }
#pragma unroll
  for (int k = 0; k < 4; k++) {
    if (k < count) {
      float3 ra = f3(p[k][6]), rb = f3(p[k][7]);
      float3 t1 = f3(h2), t2 = f3(h3);
      float v1 = dot3(t1, add3(va, mul3(vb, -1.f))) + dot3(cross3(ra, t1), wa) - dot3(cross3(rb, t1), wb);
      float v2 = dot3(t2, add3(va, mul3(vb, -1.f))) + dot3(cross3(ra, t2), wa) - dot3(cross3(rb, t2), wb);
      float w1 = p[k][3].w - v1 * p[k][2].w, w2 = p[k][5].w - v2 * p[k][4].w;
      float lim = h1.w * p[k][1].w, l2 = w1 * w1 + w2 * w2;
      float sc = l2 > lim * lim ? lim * rsqrtf(l2) : 1.f;
      float d1 = w1 * sc - p[k][3].w, d2 = w2 * sc - p[k][5].w;
      p[k][3].w = w1 * sc; p[k][5].w = w2 * sc;
      va = add3(va, mul3(t1, d1 * h3.w)); wa = add3(wa, mul3(f3(p[k][2]), d1));
      vb = add3(vb, mul3(t1, -d1 * h4.x)); wb = add3(wb, mul3(f3(p[k][3]), -d1));
      va = add3(va, mul3(t2, d2 * h3.w)); wa = add3(wa, mul3(f3(p[k][4]), d2));
      vb = add3(vb, mul3(t2, -d2 * h4.x)); wb = add3(wb, mul3(f3(p[k][5]), -d2));
    }
  }
#pragma unroll
  for (int k = 0; k < 4; k++) {
    if (k < count) {
      reinterpret_cast<float*>(&c[addr<TILED>(i, HEADER + k * POINT + 1)])[3] = p[k][1].w;
      reinterpret_cast<float*>(&c[addr<TILED>(i, HEADER + k * POINT + 3)])[3] = p[k][3].w;
      reinterpret_cast<float*>(&c[addr<TILED>(i, HEADER + k * POINT + 5)])[3] = p[k][5].w;
      reinterpret_cast<float*>(&c[addr<TILED>(i, HEADER + k * POINT + 8)])[1] = p[k][8].y;
    }
  }
  a.v = make_float4(va.x, va.y, va.z, a.v.w); a.w = make_float4(wa.x, wa.y, wa.z, 0);
  b.v = make_float4(vb.x, vb.y, vb.z, b.v.w); b.w = make_float4(wb.x, wb.y, wb.z, 0);
  bodies[h0.x] = a;
  bodies[h0.y] = b;
}

int main(int argc, char** argv) {
  int which = atoi(argv[1]);  // 0: 100k pile, 1: 500k pile, 2: 3k
  std::vector<unsigned> hist;
  unsigned nbodies;
  if (which == 0) { hist = {48671,43263,39948,36469,31996,25830,17623,9094,3240,801,163,31,8}; nbodies = 100049; }
  else if (which == 1) { hist = {236973,219580,206534,191307,170812,142816,105445,62078,27528,9198,2487,507,77,8,1}; nbodies = 499489; }
  else { hist = {1357,1221,1002,806,604,421,236,126,56,16,3,1}; nbodies = 3009; }
  std::vector<unsigned> offsets{0};
  for (auto h : hist) offsets.push_back(offsets.back() + h);
  unsigned n = offsets.back();
  std::mt19937 rng(7);
  // Constraint data: AoS image, then tiled copy.
  std::vector<float4> aos((size_t)n * SLOTS);
  std::vector<unsigned> perm(nbodies);
  for (unsigned i = 0; i < nbodies; i++) perm[i] = i;
  for (size_t b = 0; b < hist.size(); b++) {
    std::shuffle(perm.begin(), perm.end(), rng);
    unsigned m = hist[b];
    std::vector<std::pair<unsigned, unsigned>> pairs(m);
    for (unsigned j = 0; j < m; j++) {
      unsigned x = perm[2 * j], y = perm[2 * j + 1];
      pairs[j] = {std::min(x, y), std::max(x, y)};
    }
    std::sort(pairs.begin(), pairs.end());  // rows come in pair-key order
    for (unsigned j = 0; j < m; j++) {
      size_t i = offsets[b] + j;
      unsigned count = 1 + (rng() % 4 == 0 ? 3 : (rng() % 2));  // ~2 points on average
      uint4 h0 = make_uint4(pairs[j].first, pairs[j].second, (unsigned)i, count);
      aos[i * SLOTS] = *reinterpret_cast<float4*>(&h0);
      for (int s = 1; s < SLOTS; s++) aos[i * SLOTS + s] = make_float4(0.01f * s, 0.02f, -0.01f, 0.5f);
    }
  }
  std::vector<float4> tiled(((size_t)(n + 31) / 32) * 32 * SLOTS);
  for (size_t i = 0; i < n; i++)
    for (int s = 0; s < SLOTS; s++) tiled[((i >> 5) * SLOTS + s) * 32 + (i & 31)] = aos[i * SLOTS + s];
  float4 *d_aos, *d_tiled; Body* d_bodies; unsigned* d_off;
  cudaMalloc(&d_aos, aos.size() * 16); cudaMalloc(&d_tiled, tiled.size() * 16);
  cudaMalloc(&d_bodies, nbodies * sizeof(Body)); cudaMalloc(&d_off, offsets.size() * 4);
  cudaMemcpy(d_aos, aos.data(), aos.size() * 16, cudaMemcpyHostToDevice);
  cudaMemcpy(d_tiled, tiled.data(), tiled.size() * 16, cudaMemcpyHostToDevice);
  cudaMemset(d_bodies, 0, nbodies * sizeof(Body));
  cudaMemcpy(d_off, offsets.data(), offsets.size() * 4, cudaMemcpyHostToDevice);
  cudaEvent_t e0, e1; cudaEventCreate(&e0); cudaEventCreate(&e1);
  for (int tiledMode = 0; tiledMode < 2; tiledMode++) {
    for (int block : {32, 64, 128}) {
      float best = 1e9;
      for (int rep = 0; rep < 5; rep++) {
        cudaEventRecord(e0);
        for (int sweep = 0; sweep < 16; sweep++)
          for (size_t b = 0; b < hist.size(); b++) {
            unsigned groups = (hist[b] + block - 1) / block;
            if (tiledMode) solve<true><<<groups, block>>>(d_off, b, d_tiled, d_bodies);
            else solve<false><<<groups, block>>>(d_off, b, d_aos, d_bodies);
          }
        cudaEventRecord(e1); cudaEventSynchronize(e1);
        float ms; cudaEventElapsedTime(&ms, e0, e1);
        best = std::min(best, ms);
      }
      printf("scene %d n=%u %s block %3d: 16 sweeps %.3f ms (%.1f us/sweep)\n", which, n,
             tiledMode ? "tiled" : "aos  ", block, best, best * 1000 / 16);
    }
  }
  cudaError_t err = cudaGetLastError();
  printf("%s\n", cudaGetErrorString(err));
  return 0;
}
