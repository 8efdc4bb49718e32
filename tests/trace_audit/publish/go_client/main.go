// An outside tlog client of a tree `trace-audit publish` wrote, using only Go's standard
// library and golang.org/x/mod/sumdb/{note,tlog}: nothing of TRACE's code or format.
//
// It reads one JSON request on stdin:
//
//	{"url": "http://host:port/<robot>", "vkey": "<verifier key>", "index": N,
//	 "old_note": "<an older checkpoint note, optional>", "proof": "<a tlog-proof, optional>",
//	 "witness_vkey": "<a witness's tlog-cosignature/v1 verifier key, optional>"}
//
// fetches <url>/checkpoint and opens it with note.Open under the robot's verifier key (and,
// given a witness's key, requires that witness's cosignature on it too: note.Open under both
// keys, the cosignature checked by a note.Verifier written here from c2sp.org/tlog-cosignature),
// recomputes the tree's root from the hash tiles (tlog.TileHashReader verifies every tile it
// reads against the checkpoint's root), fetches entry N from its entry bundle, proves and
// checks its inclusion (tlog.ProveRecord, tlog.CheckRecord) and, given an older note, the
// consistency of the two trees (tlog.ProveTree, tlog.CheckTree). Given a c2sp.org/tlog-proof
// text, it checks that proof too, against its own checkpoint. It answers JSON on stdout,
// or one line on stderr and exit 1 at the first thing that does not verify.
package main

import (
	"bytes"
	"crypto/ed25519"
	"crypto/sha256"
	"encoding/base64"
	"encoding/binary"
	"encoding/json"
	"fmt"
	"io"
	"net/http"
	"os"
	"strconv"
	"strings"

	"golang.org/x/mod/sumdb/note"
	"golang.org/x/mod/sumdb/tlog"
)

const height = 8 // C2SP tlog-tiles: tiles are always 2^8 hashes wide

type request struct {
	URL     string `json:"url"`
	VKey    string `json:"vkey"`
	Index   int64  `json:"index"`
	OldNote string `json:"old_note"`
	Proof   string `json:"proof"`
	Witness string `json:"witness_vkey"`
}

type answer struct {
	Origin      string   `json:"origin"`
	Size        int64    `json:"size"`
	Root        string   `json:"root"`
	Entry       string   `json:"entry"`
	Inclusion   []string `json:"inclusion"`
	OldSize     int64    `json:"old_size"`
	Consistency []string `json:"consistency"`
	ProofIndex  int64    `json:"proof_index"`
	ProofSize   int64    `json:"proof_size"`
	Signers     []string `json:"signers"`
	CosignedAt  uint64   `json:"cosigned_at"`
	Fetched     []string `json:"fetched"`
}

type checkpoint struct {
	origin string
	size   int64
	root   tlog.Hash
}

var fetched []string

func get(url string) ([]byte, error) {
	resp, err := http.Get(url)
	if err != nil {
		return nil, err
	}
	defer resp.Body.Close()
	if resp.StatusCode != http.StatusOK {
		return nil, fmt.Errorf("GET %s: %s", url, resp.Status)
	}
	fetched = append(fetched, url)
	return io.ReadAll(io.LimitReader(resp.Body, 1<<24))
}

// c2spPath maps Go's tile path to C2SP's. Go's tlog.Tile.Path() is "tile/<H>/<L>/<N>[.p/<W>]"
// with the tile height as a path element (and "data" as the level of the entries); C2SP
// tlog-tiles fixes the height at 8 and drops that element ("tile/<L>/<N>[.p/<W>]"), and
// serves entry bundles at "tile/entries/<N>[.p/<W>]". The index and width are spelled alike.
func c2spPath(t tlog.Tile) (string, error) {
	goPath := t.Path()
	back, err := tlog.ParseTilePath(goPath)
	if err != nil || back != t {
		return "", fmt.Errorf("tile %v does not round-trip through %s", t, goPath)
	}
	rest := strings.TrimPrefix(goPath, fmt.Sprintf("tile/%d/", height))
	if t.L == -1 {
		return "tile/entries/" + strings.TrimPrefix(rest, "data/"), nil
	}
	return "tile/" + rest, nil
}

// tileReader is a tlog.TileReader over HTTP.
type tileReader struct{ base string }

func (r tileReader) Height() int { return height }

func (r tileReader) ReadTiles(tiles []tlog.Tile) ([][]byte, error) {
	out := make([][]byte, len(tiles))
	for i, t := range tiles {
		path, err := c2spPath(t)
		if err != nil {
			return nil, err
		}
		if out[i], err = get(r.base + "/" + path); err != nil {
			return nil, err
		}
	}
	return out, nil
}

func (r tileReader) SaveTiles([]tlog.Tile, [][]byte) {}

// parseCheckpoint reads a c2sp.org/tlog-checkpoint body: origin, size, base64 root.
func parseCheckpoint(text string) (checkpoint, error) {
	lines := strings.Split(text, "\n")
	if len(lines) < 4 {
		return checkpoint{}, fmt.Errorf("a checkpoint has at least three lines")
	}
	size, err := strconv.ParseInt(lines[1], 10, 64)
	if err != nil || size < 0 {
		return checkpoint{}, fmt.Errorf("bad checkpoint size %q", lines[1])
	}
	root, err := base64.StdEncoding.DecodeString(lines[2])
	if err != nil || len(root) != tlog.HashSize {
		return checkpoint{}, fmt.Errorf("bad checkpoint root %q", lines[2])
	}
	var h tlog.Hash
	copy(h[:], root)
	return checkpoint{lines[0], size, h}, nil
}

// cosigVerifier is a note.Verifier of c2sp.org/tlog-cosignature@v1 signatures (type 0x04):
// x/mod's note knows only Ed25519 notes, but its Verifier is an interface. A cosignature
// is the 8-byte big-endian time then the Ed25519 signature of "cosignature/v1\ntime T\n"
// followed by the note's text.
type cosigVerifier struct {
	name string
	hash uint32
	key  ed25519.PublicKey
	seen *uint64
}

func (v cosigVerifier) Name() string    { return v.name }
func (v cosigVerifier) KeyHash() uint32 { return v.hash }
func (v cosigVerifier) Verify(msg, sig []byte) bool {
	if len(sig) != 8+ed25519.SignatureSize {
		return false
	}
	t := binary.BigEndian.Uint64(sig[:8])
	signed := append([]byte(fmt.Sprintf("cosignature/v1\ntime %d\n", t)), msg...)
	if !ed25519.Verify(v.key, signed, sig[8:]) {
		return false
	}
	*v.seen = t
	return true
}

// newCosigVerifier parses "<name>+<hash>+<base64(0x04 || key)>" and checks its hash.
func newCosigVerifier(vkey string) (cosigVerifier, error) {
	parts := strings.SplitN(vkey, "+", 3) // base64 may hold a "+": name and hash never do
	if len(parts) != 3 {
		return cosigVerifier{}, fmt.Errorf("witness key: not name+hash+key")
	}
	raw, err := base64.StdEncoding.DecodeString(parts[2])
	if err != nil || len(raw) != 1+ed25519.PublicKeySize || raw[0] != 0x04 {
		return cosigVerifier{}, fmt.Errorf("witness key: not a tlog-cosignature/v1 key")
	}
	sum := sha256.Sum256(append([]byte(parts[0]+"\n"), raw...))
	hash := binary.BigEndian.Uint32(sum[:4])
	if fmt.Sprintf("%08x", hash) != parts[1] {
		return cosigVerifier{}, fmt.Errorf("witness key: wrong key hash")
	}
	return cosigVerifier{parts[0], hash, ed25519.PublicKey(raw[1:]), new(uint64)}, nil
}

func openCheckpoint(msg []byte, verifier note.Verifier) (checkpoint, error) {
	c, _, err := openCosigned(msg, verifier, nil)
	return c, err
}

// openCosigned opens a checkpoint under the log's key and, given one, a witness's: with a
// witness, its cosignature must be among the verified signatures.
func openCosigned(msg []byte, verifier note.Verifier, witness note.Verifier) (checkpoint, []string, error) {
	known := note.VerifierList(verifier)
	if witness != nil {
		known = note.VerifierList(verifier, witness)
	}
	n, err := note.Open(msg, known)
	if err != nil {
		return checkpoint{}, nil, fmt.Errorf("checkpoint: %v", err)
	}
	var signers []string
	signed := map[string]bool{}
	for _, s := range n.Sigs { // note.Open lists only the known keys' verified signatures
		signers = append(signers, s.Name)
		signed[fmt.Sprintf("%s+%08x", s.Name, s.Hash)] = true
	}
	if !signed[fmt.Sprintf("%s+%08x", verifier.Name(), verifier.KeyHash())] {
		return checkpoint{}, nil, fmt.Errorf("checkpoint: not signed by %s", verifier.Name())
	}
	if witness != nil && !signed[fmt.Sprintf("%s+%08x", witness.Name(), witness.KeyHash())] {
		return checkpoint{}, nil, fmt.Errorf("checkpoint: no cosignature by %s", witness.Name())
	}
	c, err := parseCheckpoint(n.Text)
	if err == nil && c.origin != verifier.Name() {
		err = fmt.Errorf("checkpoint of %s, not of %s", c.origin, verifier.Name())
	}
	return c, signers, err
}

// entryAt fetches entry index of a tree of size entries from its (full or partial) bundle.
func entryAt(base string, index, size int64) ([]byte, error) {
	t := tlog.Tile{H: height, L: -1, N: index >> height, W: 1 << height}
	if rest := size - t.N<<height; rest < 1<<height {
		t.W = int(rest)
	}
	path, err := c2spPath(t)
	if err != nil {
		return nil, err
	}
	data, err := get(base + "/" + path)
	if err != nil {
		return nil, err
	}
	var entries [][]byte
	for len(data) > 0 {
		if len(data) < 2 {
			return nil, fmt.Errorf("%s: ends inside a length", path)
		}
		n := int(binary.BigEndian.Uint16(data))
		if len(data) < 2+n {
			return nil, fmt.Errorf("%s: ends inside an entry", path)
		}
		entries = append(entries, data[2:2+n])
		data = data[2+n:]
	}
	if len(entries) != t.W {
		return nil, fmt.Errorf("%s: %d entries, not %d", path, len(entries), t.W)
	}
	return entries[index-t.N<<height], nil
}

func b64s(hashes []tlog.Hash) []string {
	out := make([]string, len(hashes))
	for i, h := range hashes {
		out[i] = base64.StdEncoding.EncodeToString(h[:])
	}
	return out
}

func run(req request) (answer, error) {
	var a answer
	verifier, err := note.NewVerifier(req.VKey)
	if err != nil {
		return a, err
	}
	var witness note.Verifier
	var cosigned *uint64
	if req.Witness != "" {
		w, err := newCosigVerifier(req.Witness)
		if err != nil {
			return a, err
		}
		witness, cosigned = w, w.seen
	}
	msg, err := get(req.URL + "/checkpoint")
	if err != nil {
		return a, err
	}
	cp, signers, err := openCosigned(msg, verifier, witness)
	if err != nil {
		return a, err
	}
	a.Signers = signers
	if cosigned != nil {
		a.CosignedAt = *cosigned
	}
	a.Origin, a.Size, a.Root = cp.origin, cp.size, base64.StdEncoding.EncodeToString(cp.root[:])
	hashes := tlog.TileHashReader(tlog.Tree{N: cp.size, Hash: cp.root}, tileReader{req.URL})
	root, err := tlog.TreeHash(cp.size, hashes)
	if err != nil {
		return a, fmt.Errorf("tree hash: %v", err)
	}
	if root != cp.root {
		return a, fmt.Errorf("the tiles' root %v is not the checkpoint's %v", root, cp.root)
	}
	entry, err := entryAt(req.URL, req.Index, cp.size)
	if err != nil {
		return a, err
	}
	a.Entry = base64.StdEncoding.EncodeToString(entry)
	proof, err := tlog.ProveRecord(cp.size, req.Index, hashes)
	if err != nil {
		return a, fmt.Errorf("prove record: %v", err)
	}
	if err := tlog.CheckRecord(proof, cp.size, cp.root, req.Index, tlog.RecordHash(entry)); err != nil {
		return a, fmt.Errorf("check record: %v", err)
	}
	a.Inclusion = b64s(proof)
	if req.OldNote != "" {
		old, err := openCheckpoint([]byte(req.OldNote), verifier)
		if err != nil {
			return a, fmt.Errorf("old %v", err)
		}
		tree, err := tlog.ProveTree(cp.size, old.size, hashes)
		if err != nil {
			return a, fmt.Errorf("prove tree: %v", err)
		}
		if err := tlog.CheckTree(tree, cp.size, cp.root, old.size, old.root); err != nil {
			return a, fmt.Errorf("check tree: %v", err)
		}
		a.OldSize, a.Consistency = old.size, b64s(tree)
	}
	if req.Proof != "" {
		if a.ProofIndex, a.ProofSize, err = checkTlogProof(req.Proof, verifier, entry); err != nil {
			return a, fmt.Errorf("tlog-proof: %v", err)
		}
	}
	return a, nil
}

// checkTlogProof checks a c2sp.org/tlog-proof@v1 text: its header line, "index N", the
// inclusion hashes (base64, one a line), a blank line, then the checkpoint note, which must
// verify under the robot's key; the entry is the one fetched from the tiles.
func checkTlogProof(text string, verifier note.Verifier, entry []byte) (int64, int64, error) {
	head, signed, ok := strings.Cut(text, "\n\n")
	if !ok {
		return 0, 0, fmt.Errorf("no blank line before the checkpoint")
	}
	lines := strings.Split(head, "\n")
	if len(lines) < 2 || lines[0] != "c2sp.org/tlog-proof@v1" {
		return 0, 0, fmt.Errorf("not a c2sp.org/tlog-proof@v1")
	}
	rest := lines[1:]
	if strings.HasPrefix(rest[0], "extra ") {
		rest = rest[1:]
	}
	if len(rest) == 0 || !strings.HasPrefix(rest[0], "index ") {
		return 0, 0, fmt.Errorf("no index line")
	}
	index, err := strconv.ParseInt(strings.TrimPrefix(rest[0], "index "), 10, 64)
	if err != nil {
		return 0, 0, fmt.Errorf("bad index %q", rest[0])
	}
	var proof tlog.RecordProof
	for _, line := range rest[1:] {
		h, err := base64.StdEncoding.DecodeString(line)
		if err != nil || len(h) != tlog.HashSize {
			return 0, 0, fmt.Errorf("bad hash %q", line)
		}
		var hash tlog.Hash
		copy(hash[:], h)
		proof = append(proof, hash)
	}
	cp, err := openCheckpoint([]byte(signed), verifier)
	if err != nil {
		return 0, 0, err
	}
	if err := tlog.CheckRecord(proof, cp.size, cp.root, index, tlog.RecordHash(entry)); err != nil {
		return 0, 0, err
	}
	return index, cp.size, nil
}

func main() {
	var req request
	if err := json.NewDecoder(os.Stdin).Decode(&req); err != nil {
		fmt.Fprintln(os.Stderr, "request:", err)
		os.Exit(2)
	}
	a, err := run(req)
	if err != nil {
		fmt.Fprintln(os.Stderr, err)
		os.Exit(1)
	}
	a.Fetched = fetched
	var out bytes.Buffer
	if err := json.NewEncoder(&out).Encode(a); err != nil {
		fmt.Fprintln(os.Stderr, err)
		os.Exit(1)
	}
	os.Stdout.Write(out.Bytes())
}
