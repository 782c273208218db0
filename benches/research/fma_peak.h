// The clock and the FMA-rate loop shared by the tile kernel's C models (tile_peak.c,
// tile_model.c): 24 independent AVX-512 multiply-add chains, the one-core limit.
#include <immintrin.h>
#include <time.h>
static double now(){struct timespec t;clock_gettime(CLOCK_MONOTONIC,&t);return t.tv_sec+1e-9*t.tv_nsec;}
__attribute__((noinline)) void peak(long n, float*out){
  __m512 acc[24]; for(int i=0;i<24;i++) acc[i]=_mm512_set1_ps(0.f);
  __m512 a=_mm512_set1_ps(1.0000001f), b=_mm512_set1_ps(0.999999f);
  for(long i=0;i<n;i++){
#pragma GCC unroll 24
    for(int j=0;j<24;j++) acc[j]=_mm512_fmadd_ps(a,acc[j],b);
  }
  __m512 s=acc[0]; for(int i=1;i<24;i++) s=_mm512_add_ps(s,acc[i]); _mm512_storeu_ps(out,s);
}
