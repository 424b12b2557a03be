#!/usr/bin/env python3
"""Writes the input of configs/xz.conf: make-input.py OUTPUT MIB [SEED].

MIB MiB of deterministic, compressible but not trivial data: lines of
pseudo-words drawn with a Zipf-like frequency from a 4096-word vocabulary,
each line behind a random 6-digit number, and now and then a run of random
bytes (2.5 % of the output). The same arguments give the same bytes on every
machine (Python's seeded Mersenne Twister, stdlib only; checked on Python
3.11 and 3.12). xz -6 makes it 3.6x smaller (ratio 0.27-0.28 with 1-24 MiB
blocks), and it has no long repeats, so every block of a multi-threaded xz
costs about the same. Writes 10-17 MiB/s (128 MiB: 8 s).
"""
import random
import sys


def vocabulary(rng, n=4096):
    consonants = "bcdfghjklmnprstvwz"
    vowels = "aeiou"
    words = set()
    while len(words) < n:
        syl = rng.randint(1, 4)
        words.add("".join(rng.choice(consonants) + rng.choice(vowels) +
                          (rng.choice(consonants) if rng.random() < 0.3 else "")
                          for _ in range(syl)))
    words = sorted(words)
    rng.shuffle(words)
    return words


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit("usage: make-input.py OUTPUT MIB [SEED]")
    out, mib = sys.argv[1], float(sys.argv[2])
    seed = int(sys.argv[3]) if len(sys.argv) == 4 else 1
    total = int(mib * 1024 * 1024)
    if total <= 0:
        sys.exit("make-input.py: MIB must be > 0")
    rng = random.Random(seed)
    words = vocabulary(rng)
    cum, acc = [], 0.0
    for rank in range(len(words)):
        acc += 1.0 / (rank + 1) ** 1.1
        cum.append(acc)
    punct = [" ", " ", " ", " ", " ", " ", ", ", ". ", "; ", " - "]
    written = 0
    with open(out, "wb") as f:
        while written < total:
            # One chunk: ~16k words as lines of 6..18 words, then maybe noise.
            toks = rng.choices(words, cum_weights=cum, k=16384)
            seps = rng.choices(punct, k=16384)
            lines, i = [], 0
            while i < len(toks):
                k = rng.randint(6, 18)
                body = "".join(t + s for t, s in zip(toks[i:i + k], seps[i:i + k]))
                lines.append("%06d %s\n" % (rng.randrange(1000000), body.rstrip()))
                i += k
            chunk = "".join(lines).encode("ascii")
            if rng.random() < 0.5:
                chunk += rng.randbytes(rng.randint(2048, 12288))
            chunk = chunk[:total - written]
            f.write(chunk)
            written += len(chunk)


if __name__ == "__main__":
    main()
