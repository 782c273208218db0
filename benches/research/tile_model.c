// A C model of ctsid's node x triple sweep kernel (src/engine/cpu/tiles.rs, first version:
// every node of degree <= 3 stored per block), one thread, 25,000 x 12,376 (n_z = 11, d = 6),
// random data. Used to choose the kernel's design (docs/method/regression.md, "Nodes times
// triples"). Build and run with benches/research/tile_model.sh. Switches: -DNRM=6 (4 x 6 tiles),
// -DB=512 (blocks of 512 samples); environment LATE=1 (each tile chunk's triples formed into an
// L1 buffer instead of all stored), NOTILES=1 (forming the vectors only).
#include "fma_peak.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#define NV 11
#ifndef B
#define B 256
#endif
#ifndef NRM
#define NRM 4
#endif
// nodes: deg 0..3, ordered by last var (constant first)
int nn=0; int npar[1000], nvar[1000], nlast[1000], ndeg[1000]; int Q[NV]; // Q[a] = #nodes with last var <= a (incl const)
int ntr=0; int ta[400],tb[400],tc[400], toff[NV+1]; // triples sorted by a
float *nodes, *tri, *vz, *pw; double *acc;
static inline __m512 comb1(__m512 x, __m512 y){ // 128-bit quarters: [x02, x13, y02, y13]
  return _mm512_add_ps(_mm512_shuffle_f32x4(x,y,0x44),_mm512_shuffle_f32x4(x,y,0xEE));}
static inline __m512 comb2(__m512 x, __m512 y){ // x=[A0,A1,B0,B1] -> [A0+A1? ...]
  return _mm512_add_ps(_mm512_shuffle_f32x4(x,y,0x88),_mm512_shuffle_f32x4(x,y,0xDD));}
// reduce 16 vectors to 16 sums (order permuted; we compute the permutation empirically)
static inline __m512 red16(__m512* a){
  __m512 b[8],c[4],d[2];
  for(int i=0;i<8;i++) b[i]=comb1(a[2*i],a[2*i+1]);
  for(int i=0;i<4;i++) c[i]=comb2(b[2*i],b[2*i+1]);
  // c[i]: each 128-bit lane j holds 4 partials of accumulator idx
  for(int i=0;i<2;i++){ __m512 x=c[2*i],y=c[2*i+1];
    d[i]=_mm512_add_ps(_mm512_shuffle_ps(x,y,0x44),_mm512_shuffle_ps(x,y,0xEE)); }
  return _mm512_add_ps(_mm512_shuffle_ps(d[0],d[1],0x88),_mm512_shuffle_ps(d[0],d[1],0xDD));
}
int perm[16];
#define TILE(MR,NR) static void tile_##MR##_##NR(const float*nd, const float*tr, double*out){ \
  __m512 a[32]; for(int i=0;i<32;i++) a[i]=_mm512_setzero_ps(); \
  for(int c=0;c<B;c+=16){ __m512 x[MR]; for(int r=0;r<MR;r++) x[r]=_mm512_load_ps(nd+r*B+c); \
    for(int t=0;t<NR;t++){ __m512 w=_mm512_load_ps(tr+t*B+c); for(int r=0;r<MR;r++) a[r*NRM+t]=_mm512_fmadd_ps(x[r],w,a[r*NRM+t]);} } \
  if(NRM>4){ __m512 s2=red16(a+16); __m512d lo2=_mm512_cvtps_pd(_mm512_castps512_ps256(s2)), hi2=_mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(s2),1))); \
  _mm512_store_pd(out+16,_mm512_add_pd(_mm512_load_pd(out+16),lo2)); _mm512_store_pd(out+24,_mm512_add_pd(_mm512_load_pd(out+24),hi2)); } \
  __m512 s=red16(a); __m512d lo=_mm512_cvtps_pd(_mm512_castps512_ps256(s)), hi=_mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(s),1))); \
  _mm512_store_pd(out,_mm512_add_pd(_mm512_load_pd(out),lo)); _mm512_store_pd(out+8,_mm512_add_pd(_mm512_load_pd(out+8),hi)); }
TILE(4,6) TILE(4,5) TILE(3,6) TILE(3,5) TILE(2,6) TILE(2,5) TILE(1,6) TILE(1,5) TILE(4,4) TILE(4,3) TILE(4,2) TILE(4,1) TILE(3,4) TILE(3,3) TILE(3,2) TILE(3,1) TILE(2,4) TILE(2,3) TILE(2,2) TILE(2,1) TILE(1,4) TILE(1,3) TILE(1,2) TILE(1,1)
typedef void (*tf)(const float*,const float*,double*);
tf tiles[5][7]={{0},{0,tile_1_1,tile_1_2,tile_1_3,tile_1_4,tile_1_5,tile_1_6},{0,tile_2_1,tile_2_2,tile_2_3,tile_2_4,tile_2_5,tile_2_6},{0,tile_3_1,tile_3_2,tile_3_3,tile_3_4,tile_3_5,tile_3_6},{0,tile_4_1,tile_4_2,tile_4_3,tile_4_4,tile_4_5,tile_4_6}};
long nout; float tbuf[6*B] __attribute__((aligned(64))); int late;
void block(const float* restrict z, const float* restrict v){
  for(int k=0;k<NV;k++) for(int i=0;i<B;i++) vz[k*B+i]=v[i]*z[k*B+i];
  int p=0; for(int a=0;a<NV;a++) for(int b=a;b<NV;b++){ for(int i=0;i<B;i++) pw[p*B+i]=vz[a*B+i]*z[b*B+i]; p++; }
  if(!getenv("LATE")) for(int t=0;t<ntr;t++){ int pi=0; for(int a=0;a<ta[t];a++) pi+=NV-a; pi+=tb[t]-ta[t]; const float*w=pw+pi*B,*zc=z+tc[t]*B; float*d=tri+t*B; for(int i=0;i<B;i++) d[i]=w[i]*zc[i]; }
  for(int i=0;i<B;i++) nodes[i]=1.f;
  for(int j=1;j<nn;j++){ const float*pp=nodes+npar[j]*B,*zz=z+nvar[j]*B; float*d=nodes+j*B; for(int i=0;i<B;i++) d[i]=pp[i]*zz[i]; }
  double*o=acc; if(getenv("NOTILES")) return;
  for(int a=0;a<NV;a++){ int q=Q[a];
    for(int t0=toff[a];t0<toff[a+1];t0+=NRM){ int nr=toff[a+1]-t0; if(nr>NRM)nr=NRM; const float*tb_=tri+t0*B;
      if(late){ for(int t=t0;t<t0+nr;t++){ int pi=0; for(int aa=0;aa<ta[t];aa++) pi+=NV-aa; pi+=tb[t]-ta[t]; const float*w=pw+pi*B,*zc=z+tc[t]*B; float*d=tbuf+(t-t0)*B; for(int i=0;i<B;i++) d[i]=w[i]*zc[i]; } tb_=tbuf; }
      for(int r0=0;r0<q;r0+=4){ int mr=q-r0; if(mr>4)mr=4; tiles[mr][nr](nodes+r0*B,tb_,o); o+=32; } } }
  nout=o-acc;
}
int main(int argc,char**argv){
  // perm: find where accumulator i lands
  { __m512 a[16]; for(int i=0;i<16;i++){ float e[16]={0}; e[0]=(float)(i+1); a[i]=_mm512_loadu_ps(e);} __m512 s=red16(a); float o[16]; _mm512_storeu_ps(o,s);
    for(int i=0;i<16;i++) for(int j=0;j<16;j++) if(o[j]==(float)(i+1)) perm[i]=j; }
  // nodes
  int code[1000][4];
  nn=1; ndeg[0]=0; nlast[0]=-1;
  for(int f=0;f<NV;f++){ // nodes with last var f: parents = nodes with last<=f and deg<=2, in order built so far including group f
    int start=nn;
    for(int j=0;j<nn;j++){ if(ndeg[j]<=2 && nlast[j]<=f && nlast[j]<f){ npar[nn]=j;nvar[nn]=f;nlast[nn]=f;ndeg[nn]=ndeg[j]+1;nn++; } }
    for(int j=start;j<nn;j++){ if(ndeg[j]<=2){ npar[nn]=j;nvar[nn]=f;nlast[nn]=f;ndeg[nn]=ndeg[j]+1;nn++; } }
    Q[f]=nn;
  }
  for(int a=0;a<NV;a++){ toff[a]=ntr; for(int b=a;b<NV;b++) for(int c=b;c<NV;c++){ta[ntr]=a;tb[ntr]=b;tc[ntr]=c;ntr++;} } toff[NV]=ntr;
  printf("nodes %d triples %d\n",nn,ntr);
  int nb=(25000+B-1)/B; float*Z=aligned_alloc(64,4L*nb*NV*B), *V=aligned_alloc(64,4L*nb*B);
  srand(1); for(long i=0;i<(long)nb*NV*B;i++) Z[i]=2.f*rand()/RAND_MAX-1; for(long i=0;i<(long)nb*B;i++) V[i]=2.f*rand()/RAND_MAX-1;
  nodes=aligned_alloc(64,4L*nn*B); tri=aligned_alloc(64,4L*ntr*B); vz=aligned_alloc(64,4L*NV*B); pw=aligned_alloc(64,4L*66*B); acc=aligned_alloc(64,8*80000);
  int reps=atoi(argv[1]); late=getenv("LATE")!=0;
  block(Z,V); printf("outputs %ld\n",nout);
  // check: first tile output 0: node0 (const) x triple 0 (0,0,0) => sum v z0^3 over block 0... acc accumulates; recompute
  memset(acc,0,8*80000); block(Z,V);
  { double s=0; for(int i=0;i<B;i++) s+=(double)V[i]*Z[i]*Z[i]*Z[i]; printf("check %g vs %g\n",acc[perm[0]],s);
    // tile output index for node r0+1 (z0), triple 1: acc[1*4+1]? ordering r*NR+t within tile
    double s2=0; for(int i=0;i<B;i++) s2+=(double)V[i]*Z[i]*Z[i]*Z[i]*Z[i]*Z[0*B+i+0]; }
  double t=now(); for(int r=0;r<reps;r++) for(int b=0;b<nb;b++) block(Z+(long)b*NV*B,V+(long)b*B); double tt=(now()-t)/reps;
  float o[16]; long n=20000000; double t2=now(); peak(n,o); double pr=24.0*16*n/(now()-t2);
  fprintf(stderr,"%g\n",o[0]); double fmas=12376.0*nb*B; printf("sweep %.2f ms, rate %.3g, peak %.3g, ratio to limit %.2f\n",tt*1e3,fmas/tt,pr,tt/(fmas/pr));
}
