#!/usr/bin/env python3
"""How long arena takes to build from nothing (bench/README.md "Build time").

  scripts/build_time.py sample --before REV    compiler CPU seconds of a fixed
      sample of translation units: at REV (a commit before precompiled
      headers, e.g. f597acd) without them, and in the working tree with them;
      ccache off, one compile at a time (CPU time, not wall time: it moves
      little with the machine's load)
  scripts/build_time.py headers                what a third-party header costs
      each file that includes it, as text and as a precompiled header
      (compiler CPU seconds of a file holding only the #includes; least of 3)
  scripts/build_time.py ccache                 does ccache still hit with the
      precompiled headers? A private cache and no user ccache config (the
      sloppiness comes from CMakeLists.txt), recordings/ built twice in the
      same fresh directory; exits 1 if the second build misses
  scripts/build_time.py full [--pch ON|OFF] [--unity ROOMS] [--batch N] [--arena-only]
      a fresh build directory, ccache off, -j2: wall and CPU seconds to build
      `arena`, then the rest (every test and benchmark) unless --arena-only;
      CPU seconds are the figure on a shared machine, wall seconds only on a
      quiet one. --unity compiles those rooms (ARENA_UNITY_ROOMS: ; separated,
      or all) as unity translation units of --batch files (0: the whole room)
  scripts/build_time.py arena [--every N] [--pch OFF|ON|both]   the `arena`
      target's compiler CPU seconds with ARENA_PCH OFF and/or ON in this
      tree, from a sample: every
      N-th of its compiles (ninja's order; the same files in both), one at a
      time, ccache off, plus (ON) every precompiled header it makes; scaled
      to all of its compiles (links and archives left out: the same in both).
      On a shared machine a whole fresh build takes hours of wall time; the
      sample's CPU seconds do not depend on the load
  scripts/build_time.py steps                  how many build steps
      `quickstart.sh run` takes (the `arena` target) against the whole tree,
      and which of them `arena` does not link or include (a fresh build
      directory, nothing compiled); exits 1 if `arena` builds a test or a
      benchmark
  scripts/build_time.py unity ROOM...          each room's compiler CPU seconds
      compiled one file at a time and as one unity translation unit
      (ARENA_UNITY_ROOMS, batch 0), ccache off, one compile at a time; exits 1
      when a room's unity translation unit does not compile (two of its files
      define the same file-local name)
  scripts/build_time.py clashes [ROOM...]     does every room (or these) still
      compile as one unity translation unit? Each room's unity file parsed
      (-fsyntax-only, the room's warning flags: cheap, no code made); exits 1
      naming the rooms whose files define the same file-local name twice
  scripts/build_time.py opt ROOM...            each room's compiler CPU seconds
      one file at a time at -O3 (Release's flag), -O2 and -O1, ccache off
  scripts/build_time.py packages              what a fresh Debian 12 installs for
      setup.sh: the packages setup.sh names and everything they depend on
      (no recommends, as setup.sh installs them), less the base system
      (priority required or important), with their download and installed
      sizes from this machine's apt lists

Exits non-zero when a configure or a compile fails, so a figure it printed
was made by code that builds. Build directories go under $TMPDIR.
"""
import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLE = [  # one or more per precompiled target, and two test files
    'cli/src/result_file.cpp', 'cli/src/cmd_query.cpp', 'cli/src/plot_map_data.cpp',
    'assessment/src/scoring.cpp', 'orchestrator/src/sampler.cpp', 'executors/src/defects.cpp',
    'simulators/src/arena_simulator.cpp',
    'tests/orchestrator/sampler_test.cpp', 'tests/db/store_test.cpp']
ENV = dict(os.environ, CCACHE_DISABLE='1')


def run(cmd, cwd):
    """(wall s, CPU s of the children) of a shell command; exits on failure."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.time()
    done = subprocess.run(['bash', '-c', cmd], cwd=cwd, env=ENV, capture_output=True, text=True)
    wall = time.time() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.exit(f'build_time: `{cmd}` failed in {cwd}:\n{done.stderr[-3000:]}')
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def configure(src, build, pch):
    """A fresh build directory (nothing built: the sample compiles by hand)."""
    shutil.rmtree(build, ignore_errors=True)
    run(f'cmake -S {src} -B {build} -G Ninja -DCMAKE_BUILD_TYPE=Release '
        f'-DCMAKE_CXX_COMPILER_LAUNCHER= -DARENA_PCH={pch} -DARENA_BUILD_BENCH=ON -DARENA_UNITY_ROOMS=',
        HERE)
    return json.load(open(os.path.join(build, 'compile_commands.json')))


def compile_cpu(entry, extra=''):
    return run(entry['command'].replace('/usr/bin/ccache ', '') + extra, entry['directory'])[1]


def load():
    return open('/proc/loadavg').read().split()[0]


def sample(args, root):
    """The sample's files need no generated DDS header, so each compiles alone."""
    before_src = os.path.join(root, 'before')
    os.makedirs(before_src)
    run(f'git archive {args.before} | tar -x -C {before_src}', HERE)
    cc = {'before': (before_src, configure(before_src, os.path.join(root, 'b-before'), 'OFF')),
          'after': (HERE, configure(HERE, os.path.join(root, 'b-after'), 'ON'))}
    # Each target's precompiled header, made once per fresh build.
    pchs = [e for e in cc['after'][1] if e['file'].endswith('cmake_pch.hxx.cxx')]
    pch_cpu = sum(compile_cpu(e) for e in pchs)
    print(f'| file | before: CPU s | after: CPU s |  (load {load()})')
    print(f'|---|---|---|')
    print(f'| the {len(pchs)} precompiled headers (once per build) | — | {pch_cpu:.1f} |')
    totals = {'before': 0.0, 'after': 0.0}
    files = args.files or SAMPLE
    for f in files:
        cpu = {}
        for name, (src, commands) in cc.items():
            entry = next(e for e in commands if e['file'] == os.path.join(src, f))
            # A PCH GCC refuses is parsed as text, silently: fail instead.
            cpu[name] = compile_cpu(entry, ' -Werror=invalid-pch' if name == 'after' else '')
            totals[name] += cpu[name]
        print(f"| `{f}` | {cpu['before']:.2f} | {cpu['after']:.2f} |")
    print(f"| sum of the {len(files)} files | {totals['before']:.1f} | {totals['after']:.1f} |"
          f"  (load {load()})")


HEADER_SETS = [['nlohmann/json.hpp'], ['Eigen/Core', 'Eigen/Geometry'], ['CLI/CLI.hpp'],
               ['gtest/gtest.h'], ['nlohmann/json.hpp', 'Eigen/Core', 'Eigen/Geometry'],
               ['gtest/gtest.h', 'nlohmann/json.hpp']]
FLAGS = '-std=c++20 -O3 -DNDEBUG -isystem /usr/include/eigen3 -Winvalid-pch -Werror=invalid-pch'


def headers(args, root):
    print(f'| headers | as text: CPU s | precompiled: CPU s |  (load {load()})')
    empty = os.path.join(root, 'empty.cpp')
    open(empty, 'w').write('int f() { return 1; }\n')
    for i, hs in enumerate(HEADER_SETS):
        hdr = os.path.join(root, f'h{i}.hpp')
        open(hdr, 'w').write(''.join(f'#include <{h}>\n' for h in hs))
        text = os.path.join(root, f'h{i}.cpp')
        shutil.copy(hdr, text)
        run(f'g++ {FLAGS} -x c++-header {hdr} -o {hdr}.gch', root)
        as_text = min(run(f'g++ {FLAGS} -c {text} -o /dev/null', root)[1] for _ in range(3))
        as_pch = min(run(f'g++ {FLAGS} -include {hdr} -c {empty} -o /dev/null', root)[1]
                     for _ in range(3))
        print(f"| {' + '.join(hs)} | {as_text:.2f} | {as_pch:.2f} |")


def ccache(args, root):
    env = dict(os.environ, CCACHE_DIR=os.path.join(root, 'cache'),
               CCACHE_CONFIGPATH=os.path.join(root, 'ccache.conf'))
    env.pop('CCACHE_DISABLE', None)
    open(env['CCACHE_CONFIGPATH'], 'w').close()
    build = os.path.join(root, 'build')
    sh = lambda cmd: subprocess.run(['bash', '-c', cmd], env=env, check=True, capture_output=True,
                                    text=True).stdout
    for round_ in (1, 2):
        shutil.rmtree(build, ignore_errors=True)
        sh(f'cmake -S {HERE} -B {build} -G Ninja -DCMAKE_BUILD_TYPE=Release -DARENA_PCH=ON')
        objs = sh(f"ninja -C {build} -t targets all | grep -oE '^recordings/CMakeFiles/arena_recordings"
                  f"\\.dir/(src/[a-z_]+\\.cpp\\.o|cmake_pch\\.hxx\\.gch)' | sort -u").split()
        sh('ccache -z')
        sh(f'ninja -C {build} -j2 {" ".join(objs)}')
        stats = dict(line.split('\t') for line in sh('ccache --print-stats').splitlines() if '\t' in line)
        hits = int(stats['direct_cache_hit']) + int(stats['preprocessed_cache_hit'])
        print(f"| build {round_} | {len(objs)} compiles | {hits} hits | {stats['cache_miss']} misses | "
              f"{stats['could_not_use_precompiled_header']} could not use the PCH |")
    if int(stats['cache_miss']) != 0:
        sys.exit('build_time: the second build missed the cache')


def full(args, root):
    build = os.path.join(root, 'build')
    shutil.rmtree(build, ignore_errors=True)
    run(f'cmake -S {HERE} -B {build} -G Ninja -DCMAKE_BUILD_TYPE=Release '
        f'-DCMAKE_CXX_COMPILER_LAUNCHER= -DARENA_PCH={args.pch} "-DARENA_UNITY_ROOMS={args.unity}" '
        f'-DARENA_UNITY_BATCH={args.batch}', HERE)
    print(f'load {load()}')
    wall, cpu = run('ninja -j2 bin/arena', build)
    print(f'| arena | {wall:.0f} | {cpu:.0f} |  (ARENA_PCH={args.pch}, '
          f'ARENA_UNITY_ROOMS="{args.unity}", batch {args.batch}, load {load()})')
    if args.arena_only:
        return
    wall2, cpu2 = run('ninja -j2', build)
    print(f'| everything else | {wall2:.0f} | {cpu2:.0f} |')
    print(f'| all | {wall + wall2:.0f} | {cpu + cpu2:.0f} |  (load {load()})')


def arena_plan(build):
    """ninja's commands for bin/arena: (generators, precompiled headers, compiles)."""
    cmds = subprocess.run(['ninja', '-C', build, '-t', 'commands', 'bin/arena'], capture_output=True,
                          text=True, check=True).stdout.splitlines()
    generators = [c for c in cmds if 'fastddsgen' in c or 'version.cmake' in c]
    compiles = [c for c in cmds if ' -c ' in c]
    pchs = [c for c in compiles if 'cmake_pch.hxx.cxx' in c]
    return generators, pchs, [c for c in compiles if c not in pchs]


def source_of(command, build):
    """The compiled file; a generated one named relative to its build directory."""
    return command.split(' -c ')[-1].split()[0].replace(build, '<build>')


def compile_by_hand(command, build):
    """CPU seconds of one of ninja's compile commands, run in the build directory."""
    out = command.split(' -o ')[1].split()[0]
    os.makedirs(os.path.join(build, os.path.dirname(out)), exist_ok=True)
    # A precompiled header GCC refuses is parsed as text, silently: fail instead.
    return run(command.replace('/usr/bin/ccache ', '') + ' -Werror=invalid-pch', build)[1]


def arena(args, root):
    plans = {}
    for pch in ('OFF', 'ON'):  # both configured: the file lists must agree
        build = os.path.join(root, 'b-' + pch)
        # One file per compile: the sample is of files (full --unity measures unity builds).
        run(f'cmake -S {HERE} -B {build} -G Ninja -DCMAKE_BUILD_TYPE=Release '
            f'-DCMAKE_CXX_COMPILER_LAUNCHER= -DARENA_PCH={pch} -DARENA_UNITY_ROOMS=', HERE)
        plans[pch] = (build,) + arena_plan(build)
    off_sources = [source_of(c, plans['OFF'][0]) for c in plans['OFF'][3]]
    if sorted(off_sources) != sorted(source_of(c, plans['ON'][0]) for c in plans['ON'][3]):
        sys.exit('build_time: ARENA_PCH ON and OFF compile different files for arena')
    sample = off_sources[::args.every]
    print(f'| ARENA_PCH | precompiled headers: CPU s | {len(sample)} of {len(off_sources)} files: '
          f'CPU s | arena\'s compiles, scaled: CPU s |  (load {load()})')
    print('|---|---|---|---|')
    for pch, (build, generators, pchs, compiles) in plans.items():
        if args.pch not in (pch, 'both'):
            continue
        for g in generators:
            run(g, build)  # the generated DDS types and version.cpp, not timed
        pch_cpu = sum(compile_by_hand(c, build) for c in pchs)
        by_source = {source_of(c, build): c for c in compiles}
        files_cpu = sum(compile_by_hand(by_source[f], build) for f in sample)
        scaled = pch_cpu + files_cpu * len(off_sources) / len(sample)
        print(f'| {pch} | {pch_cpu:.1f} ({len(pchs)}) | {files_cpu:.1f} | {scaled:.0f} |'
              f'  (load {load()})', flush=True)


def steps(args, root):
    """What `quickstart.sh run` (setup.sh --target arena) builds: ninja's own plan."""
    build = os.path.join(root, 'build')
    run(f'cmake -S {HERE} -B {build} -G Ninja -DCMAKE_BUILD_TYPE=Release', HERE)
    plan = lambda target: subprocess.run(['ninja', '-C', build, '-t', 'commands'] + target,
                                         capture_output=True, text=True, check=True).stdout.splitlines()
    arena, everything = plan(['bin/arena']), plan([])
    compiles = [c for c in arena if ' -c ' in c]
    # A test or benchmark source in arena's plan is a step the campaign never runs.
    waste = [c for c in compiles if ' -c ' + HERE + '/tests/' in c or ' -c ' + HERE + '/bench/' in c
             or ' -c tests/' in c or ' -c bench/' in c]
    print(f'| plan | steps | compiles |')
    print(f'|---|---|---|')
    print(f'| `arena` (quickstart.sh run) | {len(arena)} | {len(compiles)} |')
    print(f"| everything (quickstart.sh test) | {len(everything)} | "
          f"{sum(' -c ' in c for c in everything)} |")
    print(f'test or benchmark compiles in the arena plan: {len(waste)}')
    if waste:
        sys.exit('build_time: `arena` builds a test or a benchmark:\n' + '\n'.join(waste[:10]))


def unity(args, root):
    plans = {}
    for mode, rooms in (('OFF', ''), ('ON', 'all')):
        build = os.path.join(root, 'u-' + mode)
        run(f'cmake -S {HERE} -B {build} -G Ninja -DCMAKE_BUILD_TYPE=Release '
            f'-DCMAKE_CXX_COMPILER_LAUNCHER= -DARENA_PCH=OFF -DARENA_UNITY_ROOMS={rooms} '
            f'-DARENA_UNITY_BATCH=0', HERE)
        plans[mode] = (build,) + arena_plan(build)
        for g in plans[mode][1]:
            run(g, build)  # the generated DDS types and version.cpp, not timed
    print(f'| room | files | one at a time: CPU s | unity: CPU s |  (load {load()})')
    print('|---|---|---|---|')
    failed = []
    for room in args.rooms:
        ours = lambda mode: [c for c in plans[mode][3] if f' -o {room}/CMakeFiles/arena_{room}.dir/' in c]
        files, unity_tus = ours('OFF'), ours('ON')
        if not files:
            sys.exit(f'build_time: {room} is not a room of arena with files of its own')
        try:  # first: a room whose files clash costs only its failed unity compile
            cpu_unity = sum(compile_by_hand(c, plans['ON'][0]) for c in unity_tus)
        except SystemExit as e:
            errors = [l for l in str(e.code).splitlines() if 'error:' in l]
            print('\n'.join(errors[:20]), file=sys.stderr)
            failed.append(room)
            print(f'| {room} | {len(files)} | — | does not compile |', flush=True)
            continue
        cpu_files = sum(compile_by_hand(c, plans['OFF'][0]) for c in files)
        print(f'| {room} | {len(files)} | {cpu_files:.1f} | {cpu_unity:.1f} ({len(unity_tus)} '
              f'compiles) |  (load {load()})', flush=True)
    if failed:
        sys.exit(f'build_time: no unity build for {", ".join(failed)}')


def clashes(args, root):
    build = os.path.join(root, 'build')
    run(f'cmake -S {HERE} -B {build} -G Ninja -DCMAKE_BUILD_TYPE=Release '
        f'-DCMAKE_CXX_COMPILER_LAUNCHER= -DARENA_PCH=OFF -DARENA_UNITY_ROOMS=all', HERE)
    generators, _, compiles = arena_plan(build)
    for g in generators:
        run(g, build)  # the generated DDS types the rooms include
    print('| room | unity translation unit |')
    print('|---|---|')
    failed = []
    for c in compiles:
        if '/Unity/unity_' not in c:
            continue
        room = c.split(' -o ')[1].split('/')[0]
        if args.rooms and room not in args.rooms:
            continue
        cmd = c.split(' -o ')[0] + ' -fsyntax-only -Werror ' + ' '.join(c.split(' -o ')[1].split()[1:])
        done = subprocess.run(['bash', '-c', cmd.replace('/usr/bin/ccache ', '')], cwd=build,
                              env=ENV, capture_output=True, text=True)
        if done.returncode != 0:
            failed.append(room)
            errors = [l for l in done.stderr.splitlines() if 'error' in l]
            print('\n'.join(errors[:20]), file=sys.stderr)
        print(f"| {room} | {'parses clean' if done.returncode == 0 else 'does not compile'} |",
              flush=True)
    if failed:
        sys.exit(f'build_time: no unity build for {", ".join(failed)}')


def opt(args, root):
    build = os.path.join(root, 'build')
    run(f'cmake -S {HERE} -B {build} -G Ninja -DCMAKE_BUILD_TYPE=Release '
        f'-DCMAKE_CXX_COMPILER_LAUNCHER= -DARENA_PCH=OFF -DARENA_UNITY_ROOMS=', HERE)
    generators, _, compiles = arena_plan(build)
    for g in generators:
        run(g, build)
    print(f'| room | files | -O3: CPU s | -O2: CPU s | -O1: CPU s |  (load {load()})')
    print('|---|---|---|---|---|')
    for room in args.rooms:
        files = [c for c in compiles if f' -o {room}/CMakeFiles/arena_{room}.dir/' in c]
        if ' -O3 ' not in files[0]:
            sys.exit('build_time: Release no longer compiles with -O3')
        cpu = {o: sum(compile_by_hand(c.replace(' -O3 ', f' {o} '), build) for c in files)
               for o in ('-O3', '-O2', '-O1')}
        print(f"| {room} | {len(files)} | {cpu['-O3']:.1f} | {cpu['-O2']:.1f} | {cpu['-O1']:.1f} |"
              f'  (load {load()})', flush=True)


def setup_packages():
    """The package names of setup.sh's `packages=(...)` array (comments dropped)."""
    text = open(os.path.join(HERE, 'scripts', 'setup.sh')).read()
    body = text.split('packages=(', 1)[1].split('\n)', 1)[0]
    return [w for line in body.splitlines() for w in line.split('#', 1)[0].split()]


def packages(args, root):
    names = setup_packages()
    out = subprocess.run(['apt-cache', 'depends', '--recurse', '--no-recommends', '--no-suggests',
                          '--no-conflicts', '--no-breaks', '--no-replaces', '--no-enhances'] + names,
                         capture_output=True, text=True, check=True).stdout
    closure = sorted({l for l in out.splitlines() if l and not l.startswith((' ', '<'))})
    show = subprocess.run(['apt-cache', 'show', '--no-all-versions'] + closure,
                          capture_output=True, text=True, check=True).stdout
    count, download, installed = 0, 0, 0
    for record in show.split('\n\n'):
        fields = dict(l.split(': ', 1) for l in record.splitlines() if ': ' in l and l[0] != ' ')
        if 'Package' not in fields or fields.get('Priority') in ('required', 'important'):
            continue
        count += 1
        download += int(fields.get('Size', 0))
        installed += int(fields.get('Installed-Size', 0)) * 1024
    print('| setup.sh names | packages a fresh Debian 12 installs | download: MB | installed: MB |')
    print('|---|---|---|---|')
    print(f'| {len(names)} | {count} | {download / 1e6:.0f} | {installed / 1e6:.0f} |')


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest='mode', required=True)
    s = sub.add_parser('sample')
    s.add_argument('--before', required=True)
    s.add_argument('--files', nargs='*', help='these files instead of the fixed sample')
    sub.add_parser('headers')
    sub.add_parser('ccache')
    sub.add_parser('steps')
    sub.add_parser('packages')
    c = sub.add_parser('clashes')
    c.add_argument('rooms', nargs='*', help='rooms (default: all)')
    o = sub.add_parser('opt')
    o.add_argument('rooms', nargs='+', help='rooms, e.g. simulators')
    u = sub.add_parser('unity')
    u.add_argument('rooms', nargs='+', help='rooms, e.g. mechanics simulators')
    a = sub.add_parser('arena')
    a.add_argument('--every', type=int, default=6, help='compile every N-th of arena\'s files')
    a.add_argument('--pch', default='both', choices=['OFF', 'ON', 'both'])
    f = sub.add_parser('full')
    f.add_argument('--pch', default='ON', choices=['ON', 'OFF'])
    f.add_argument('--unity', default='', help='ARENA_UNITY_ROOMS: rooms, ; separated, or all')
    f.add_argument('--batch', type=int, default=0, help='files per unity translation unit')
    f.add_argument('--arena-only', action='store_true', help='stop after the arena binary')
    args = p.parse_args()
    root = tempfile.mkdtemp(prefix='arena-build-time-')
    try:
        {'sample': sample, 'headers': headers, 'ccache': ccache, 'full': full,
         'steps': steps, 'arena': arena, 'packages': packages, 'unity': unity, 'opt': opt,
         'clashes': clashes}[args.mode](args, root)
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == '__main__':
    main()
