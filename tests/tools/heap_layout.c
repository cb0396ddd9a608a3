/* heap_layout.c: an LD_PRELOAD log of where the large blocks of a run are placed in the heap
 * (docs/benchmarks.md, issue 20, branch paper16). tests/tools/heap_peak.c lists what is alive at
 * the peak of the live blocks; this one records every allocation and release of at least 8 MB
 * with its address, the live sum and a call stack, so that the heap's high-water mark (the end
 * of the highest block ever placed: the pages a run touches, with glibc's heap never trimmed)
 * can be told apart from the live peak. A block released and then split by a smaller one that
 * stays keeps the next block of its size from reusing the hole: heap_layout_report.py prints
 * each new high-water mark with the function that placed it.
 *   cc -O1 -shared -fPIC -o heap_layout.so tests/tools/heap_layout.c -ldl -lpthread
 *   LD_PRELOAD=./heap_layout.so HEAP_LAYOUT_OUT=layout.log build/bin/monolith run ...
 *   python3 tests/tools/heap_layout_report.py layout.log build/bin/monolith
 * Lines: "M <maps line>" (the executable's mappings), then "A|F size ptr live L peak P t T |
 * return addresses". */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <execinfo.h>
#include <pthread.h>
#include <unistd.h>
#include <time.h>
static void* (*rmalloc)(size_t); static void (*rfree)(void*); static void* (*rrealloc)(void*,size_t);
static void* (*rcalloc)(size_t,size_t); static int (*rpm)(void**,size_t,size_t);
#define N 4096
static void* ptrs[N]; static size_t sizes[N]; static long live=0, peak=0; static int top=0;
static pthread_mutex_t mu=PTHREAD_MUTEX_INITIALIZER; static FILE* out; static int inlog=0;
static char buf[1<<16];
static double now(){struct timespec t; clock_gettime(CLOCK_MONOTONIC,&t); return t.tv_sec+t.tv_nsec*1e-9;}
static void init(){ if(!rmalloc){ rmalloc=dlsym(RTLD_NEXT,"malloc"); rfree=dlsym(RTLD_NEXT,"free"); rrealloc=dlsym(RTLD_NEXT,"realloc"); rcalloc=dlsym(RTLD_NEXT,"calloc"); rpm=dlsym(RTLD_NEXT,"posix_memalign");}
 if(!out){ const char* p=getenv("HEAP_LAYOUT_OUT"); out=fopen(p?p:"heap_layout.log","w"); setvbuf(out,buf,_IOFBF,sizeof buf); FILE* m=fopen("/proc/self/maps","r"); char l[512]; while(m&&fgets(l,512,m)) if(strstr(l,"r-xp")||strstr(l,"r--p 00000000")) fprintf(out,"M %s",l); if(m) fclose(m);} }
static void logit(const char* op, void* p, size_t sz){
  if(inlog) return; inlog=1;
  void* bt[12]; int n=backtrace(bt,12);
  fprintf(out,"%s %zu %p live %ld peak %ld t %.3f |",op,sz,p,live,peak,now());
  for(int i=2;i<n;i++) fprintf(out," %p",bt[i]);
  fprintf(out,"\n"); fflush(out); inlog=0; }
static void add(void* p,size_t sz){ if(sz<(8u<<20)||!p) return; pthread_mutex_lock(&mu); init();
  for(int i=0;i<N;i++) if(!ptrs[i]){ptrs[i]=p;sizes[i]=sz; if(i+1>top) top=i+1; break;}
  live+=sz; if(live>peak)peak=live; logit("A",p,sz); pthread_mutex_unlock(&mu);}
static void rem(void* p){ if(!p||!top) return; int hit=0; for(int i=0;i<top;i++) if(ptrs[i]==p){hit=1;break;} if(!hit) return; pthread_mutex_lock(&mu);
  for(int i=0;i<top;i++) if(ptrs[i]==p){ live-=sizes[i]; ptrs[i]=0; init(); logit("F",p,sizes[i]); break;}
  pthread_mutex_unlock(&mu);}
void* malloc(size_t s){ if(!rmalloc) init(); void* p=rmalloc(s); if(s>=(8u<<20)) add(p,s); return p;}
void free(void* p){ if(!rfree) init(); if(p && !inlog) rem(p); rfree(p);}
void* calloc(size_t a,size_t b){ if(!rcalloc){ /* dlsym may call calloc */ static char tmp[4096]; static int used=0; if(!used){used=1; return tmp;} init(); }
  void* p=rcalloc(a,b); if(a*b>=(8u<<20)) add(p,a*b); return p;}
void* realloc(void* q,size_t s){ if(!rrealloc) init(); if(q) rem(q); void* p=rrealloc(q,s); if(s>=(8u<<20)) add(p,s); return p;}
int posix_memalign(void** r,size_t al,size_t s){ if(!rpm) init(); int e=rpm(r,al,s); if(!e && s>=(8u<<20)) add(*r,s); return e;}
