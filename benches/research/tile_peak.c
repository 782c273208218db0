// One 32 x 12 broadcast register tile (AVX-512) against an FMA loop of 24 independent
// accumulators, one thread: the fraction of this CPU's multiply-add rate a GEMM-like tile reaches
// with its data in L1 or L2 (docs/method/regression.md, "Nodes times triples"). Arguments:
// K (samples per tile), tiles, repetitions. Build and run with benches/research/tile_model.sh.
#include "fma_peak.h"
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
// tile: A packed [K][32], B packed [K][12]; C 32x12
__attribute__((noinline)) void tile(int K, const float*A, const float*B, float*C){
  __m512 c[24]; for(int i=0;i<24;i++) c[i]=_mm512_setzero_ps();
  for(int k=0;k<K;k++){
    __m512 a0=_mm512_load_ps(A+32*k), a1=_mm512_load_ps(A+32*k+16);
#pragma GCC unroll 12
    for(int j=0;j<12;j++){ __m512 b=_mm512_set1_ps(B[12*k+j]); c[2*j]=_mm512_fmadd_ps(a0,b,c[2*j]); c[2*j+1]=_mm512_fmadd_ps(a1,b,c[2*j+1]); }
  }
  for(int j=0;j<12;j++){ _mm512_storeu_ps(C+32*j, _mm512_add_ps(_mm512_loadu_ps(C+32*j),c[2*j])); _mm512_storeu_ps(C+32*j+16,_mm512_add_ps(_mm512_loadu_ps(C+32*j+16),c[2*j+1]));}
}
int main(int argc,char**argv){
  int K=atoi(argv[1]); int ntiles=atoi(argv[2]); long reps=atol(argv[3]);
  float*A=aligned_alloc(64,sizeof(float)*32*K*ntiles); float*B=aligned_alloc(64,sizeof(float)*12*K+64); float*C=aligned_alloc(64,sizeof(float)*384*ntiles);
  for(long i=0;i<32L*K*ntiles;i++)A[i]=1e-3f*(i%97); for(int i=0;i<12*K;i++)B[i]=1e-3f*(i%89); for(int i=0;i<384*ntiles;i++)C[i]=0;
  float o[16]; double t=now(); long n=reps*K*ntiles/2; peak(n,o); double tp=now()-t; double peakrate=24.0*16*n/tp;
  t=now(); for(long r=0;r<reps;r++) for(int i=0;i<ntiles;i++) tile(K,A+32L*K*i,B,C+384*i); double tt=now()-t;
  double rate=(double)reps*ntiles*K*384/tt;
  printf("K=%d tiles=%d A=%ld KB peak %.3g tile %.3g  eff %.2f (%g)\n",K,ntiles,32L*K*ntiles*4/1024,peakrate,rate,rate/peakrate,o[0]+C[5]);
}
