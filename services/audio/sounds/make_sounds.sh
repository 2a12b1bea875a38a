#!/bin/sh
# Regenerates greeting.wav and farewell.wav (committed, so nothing is needed at run time).
# Needs espeak-ng and sox. 22.05 kHz mono 16-bit keeps each file about 120 kB.
set -eu
cd "$(dirname "$0")"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
chime() {  # chime OUT FREQ1 FREQ2: two soft bell-like notes
    sox -n -r 22050 -c 1 -b 16 "$tmp/a.wav" synth 0.18 sine "$2" fade q 0.005 0.18 0.14 vol 0.35
    sox -n -r 22050 -c 1 -b 16 "$tmp/b.wav" synth 0.30 sine "$3" fade q 0.005 0.30 0.26 vol 0.35
    sox "$tmp/a.wav" "$tmp/b.wav" "$1"
}
speak() {  # speak OUT TEXT
    espeak-ng -v en-us+f3 -s 150 -p 60 -w "$tmp/raw.wav" "$2"
    sox "$tmp/raw.wav" -r 22050 -c 1 -b 16 "$1" norm -3
}
chime "$tmp/up.wav" 660 880
chime "$tmp/down.wav" 880 660
speak "$tmp/hello.wav" "Hello! Nice to see you."
speak "$tmp/bye.wav" "Goodbye! See you soon."
sox "$tmp/up.wav" "$tmp/hello.wav" greeting.wav
sox "$tmp/bye.wav" "$tmp/down.wav" farewell.wav
ls -l greeting.wav farewell.wav
