// Round 35 (docs/PERFORMANCE.md): what starting a thread costs here, as TaskPool's
// constructor pays it (and the skinning pass's, which starts its pool inside its timing):
// medians over 2000 threads of the time until std::thread's constructor returns and until
// the new thread runs.
//   g++ -O2 -o /tmp/thread_start bench/experiments/round35-thread-start.cc -lpthread
//   /tmp/thread_start
#include <thread>
#include <chrono>
#include <cstdio>
#include <vector>
#include <algorithm>
#include <atomic>
int main(){ std::vector<double> c, s;
 for(int i=0;i<2000;i++){ std::atomic<bool> started{false}; auto t0=std::chrono::steady_clock::now(); std::thread t([&]{ started=true; }); auto t1=std::chrono::steady_clock::now(); while(!started) {} auto t2=std::chrono::steady_clock::now(); t.join();
 c.push_back(std::chrono::duration<double,std::micro>(t1-t0).count()); s.push_back(std::chrono::duration<double,std::micro>(t2-t0).count()); }
 std::sort(c.begin(),c.end()); std::sort(s.begin(),s.end()); printf("create %.1f us, started %.1f us\n", c[c.size()/2], s[s.size()/2]); }
