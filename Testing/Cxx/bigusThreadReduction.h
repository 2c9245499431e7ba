/**
 * @file bigusThreadReduction.h
 * @brief Data-parallel training inside one test process: threads stand for the processes of `mpirun -n P`, each
 *        with its own engine, and bigus::ProcessReduction's sums run between them.
 *
 * The sums combine every thread's values element-wise in rank order (rank 0 first), so a run repeats bit for bit,
 * as an MPI AllReduce of a fixed communicator does. A test drives it with RunOnThreads.
 */
#ifndef bigusThreadReduction_h
#define bigusThreadReduction_h

#include "bigusTrainingEngine.h"

#include <algorithm>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace bigus
{
namespace test
{

/// What the threads of one run share: a barrier and where each thread's values are.
class ThreadGroup
{
public:
  explicit ThreadGroup(int size)
    : Size(size)
    , Values(static_cast<std::size_t>(size))
    , Counts(static_cast<std::size_t>(size))
  {}

  /// Every thread of the group calls it with its own @p values ([count]); each gets the element-wise @p combine
  /// of all of them, in rank order. False with @p error on every thread when the counts differ.
  template <class T, class Combine>
  bool AllReduce(int rank, T* values, std::size_t count, Combine combine, std::string* error)
  {
    this->Values[rank] = values;
    this->Counts[rank] = count;
    this->Wait();
    const bool same =
      std::all_of(this->Counts.begin(), this->Counts.end(), [count](std::size_t c) { return c == count; });
    std::vector<T> result;
    if (same)
    {
      const T* first = static_cast<const T*>(this->Values[0]);
      result.assign(first, first + count);
      for (int r = 1; r < this->Size; ++r)
      {
        const T* other = static_cast<const T*>(this->Values[r]);
        for (std::size_t k = 0; k < count; ++k)
        {
          result[k] = combine(result[k], other[k]);
        }
      }
    }
    this->Wait(); // every thread has read the others' values before any overwrites its own
    if (!same)
    {
      *error = "the processes reduce arrays of different lengths";
      return false;
    }
    std::copy(result.begin(), result.end(), values);
    return true;
  }

private:
  void Wait()
  {
    std::unique_lock<std::mutex> lock(this->Mutex);
    const std::uint64_t generation = this->Generation;
    if (++this->Arrived == this->Size)
    {
      this->Arrived = 0;
      ++this->Generation;
      this->Released.notify_all();
      return;
    }
    this->Released.wait(lock, [&] { return this->Generation != generation; });
  }

  const int Size;
  std::vector<void*> Values;
  std::vector<std::size_t> Counts;
  std::mutex Mutex;
  std::condition_variable Released;
  int Arrived = 0;
  std::uint64_t Generation = 0;
};

/// One thread's ProcessReduction over its ThreadGroup.
class ThreadReduction : public ProcessReduction
{
public:
  ThreadReduction(ThreadGroup& group, int rank, int size)
    : Group(group)
    , ThisRank(rank)
    , Processes(size)
  {}
  int Rank() const override { return this->ThisRank; }
  int Size() const override { return this->Processes; }
  bool Sum(float* values, std::size_t count, std::string* error) override
  {
    return this->Group.AllReduce(this->ThisRank, values, count, std::plus<float>(), error);
  }
  bool Sum(double* values, std::size_t count, std::string* error) override
  {
    return this->Group.AllReduce(this->ThisRank, values, count, std::plus<double>(), error);
  }
  bool Maximum(double* values, std::size_t count, std::string* error) override
  {
    return this->Group.AllReduce(
      this->ThisRank, values, count, [](double a, double b) { return std::max(a, b); }, error);
  }
  bool Maximum(unsigned char* values, std::size_t count, std::string* error) override
  {
    return this->Group.AllReduce(
      this->ThisRank, values, count, [](unsigned char a, unsigned char b) { return std::max(a, b); }, error);
  }

private:
  ThreadGroup& Group;
  const int ThisRank, Processes;
};

/// Runs @p work(rank, reduction) on @p size threads, each with its ThreadReduction, and waits for all of them.
/// Every collective call must be made by every thread (a thread that returns early leaves the others waiting).
template <class Work>
void RunOnThreads(int size, Work work)
{
  ThreadGroup group(size);
  std::vector<std::thread> threads;
  for (int rank = 0; rank < size; ++rank)
  {
    threads.emplace_back([&group, &work, rank, size] {
      ThreadReduction reduction(group, rank, size);
      work(rank, reduction);
    });
  }
  for (std::thread& thread : threads)
  {
    thread.join();
  }
}

} // namespace test
} // namespace bigus

#endif
