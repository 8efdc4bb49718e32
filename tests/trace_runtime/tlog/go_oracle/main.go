// The reference implementations as an oracle for trace_runtime.tlog.merkle and
// trace_runtime.tlog.signed_note: golang.org/x/mod/sumdb/note (signed notes) and
// golang.org/x/mod/sumdb/tlog (RFC 6962 trees and proofs).
//
// It reads one JSON request on stdin and writes one JSON answer on stdout;
// tests/trace_runtime/tlog/test_go_oracle.py builds and drives it. Bytes travel as
// standard base64.
package main

import (
	"crypto/ed25519"
	"crypto/sha256"
	"encoding/base64"
	"encoding/binary"
	"encoding/json"
	"fmt"
	"os"

	"golang.org/x/mod/sumdb/note"
	"golang.org/x/mod/sumdb/tlog"
)

type openRequest struct {
	Note  string   `json:"note"`
	Vkeys []string `json:"vkeys"`
}

type openAnswer struct {
	Error    string   `json:"error"`
	Text     string   `json:"text"`
	Verified []string `json:"verified"`
	Unknown  []string `json:"unknown"`
}

type signRequest struct {
	Text string `json:"text"`
	Name string `json:"name"`
	Seed []byte `json:"seed"` // 32 bytes; empty: a key from note.GenerateKey
}

type signAnswer struct {
	Error string `json:"error"`
	Note  string `json:"note"`
	Vkey  string `json:"vkey"`
}

type recordCheck struct {
	Size  int64    `json:"size"`
	Index int64    `json:"index"`
	Proof [][]byte `json:"proof"`
	Root  []byte   `json:"root"`
}

type treeCheck struct {
	Old     int64    `json:"old"`
	New     int64    `json:"new"`
	Proof   [][]byte `json:"proof"`
	OldRoot []byte   `json:"old_root"`
	NewRoot []byte   `json:"new_root"`
}

type request struct {
	Open     []openRequest `json:"open"`
	Sign     []signRequest `json:"sign"`
	Leaves   [][]byte      `json:"leaves"`        // record data, in order
	Roots    []int64       `json:"roots"`         // tree sizes whose tlog.TreeHash to return
	Records  []recordCheck `json:"records"`       // tlog.CheckRecord each
	Trees    []treeCheck   `json:"trees"`         // tlog.CheckTree each
	NodePair [][]byte      `json:"node_pair"`     // two hashes for tlog.NodeHash
	Prove    [][2]int64    `json:"prove_records"` // (size, index): tlog.ProveRecord
	ProveOld [][2]int64    `json:"prove_trees"`   // (old size, new size): tlog.ProveTree
}

type answer struct {
	Open        []openAnswer `json:"open"`
	Sign        []signAnswer `json:"sign"`
	RecordHash  [][]byte     `json:"record_hashes"`
	Roots       [][]byte     `json:"roots"`
	Records     []string     `json:"records"` // "" when the proof verifies, else the error
	Trees       []string     `json:"trees"`
	NodeHash    []byte       `json:"node_hash"`
	ProveRecord [][][]byte   `json:"prove_records"`
	ProveTree   [][][]byte   `json:"prove_trees"`
}

func hashBytes(hs []tlog.Hash) [][]byte {
	out := make([][]byte, len(hs))
	for i := range hs {
		out[i] = hs[i][:]
	}
	return out
}

func toHash(b []byte) (tlog.Hash, error) {
	var h tlog.Hash
	if len(b) != len(h) {
		return h, fmt.Errorf("not a %d-byte hash", len(h))
	}
	copy(h[:], b)
	return h, nil
}

func toHashes(bs [][]byte) ([]tlog.Hash, error) {
	out := make([]tlog.Hash, len(bs))
	for i, b := range bs {
		h, err := toHash(b)
		if err != nil {
			return nil, err
		}
		out[i] = h
	}
	return out, nil
}

func openNote(r openRequest) openAnswer {
	var verifiers []note.Verifier
	for _, vk := range r.Vkeys {
		v, err := note.NewVerifier(vk)
		if err != nil {
			return openAnswer{Error: "verifier: " + err.Error()}
		}
		verifiers = append(verifiers, v)
	}
	n, err := note.Open([]byte(r.Note), note.VerifierList(verifiers...))
	if err != nil {
		return openAnswer{Error: err.Error()}
	}
	a := openAnswer{Text: n.Text, Verified: []string{}, Unknown: []string{}}
	for _, s := range n.Sigs {
		a.Verified = append(a.Verified, fmt.Sprintf("%s+%08x", s.Name, s.Hash))
	}
	for _, s := range n.UnverifiedSigs {
		a.Unknown = append(a.Unknown, fmt.Sprintf("%s+%08x", s.Name, s.Hash))
	}
	return a
}

// signerKey spells a note signer key for an Ed25519 seed, as note.GenerateKey does.
func signerKey(name string, seed []byte) (string, string, error) {
	if len(seed) != ed25519.SeedSize {
		return "", "", fmt.Errorf("a seed is %d bytes", ed25519.SeedSize)
	}
	pub := ed25519.NewKeyFromSeed(seed).Public().(ed25519.PublicKey)
	vkey, err := note.NewEd25519VerifierKey(name, pub)
	if err != nil {
		return "", "", err
	}
	h := sha256.New()
	h.Write([]byte(name + "\n"))
	h.Write(append([]byte{1}, pub...))
	id := binary.BigEndian.Uint32(h.Sum(nil))
	skey := fmt.Sprintf("PRIVATE+KEY+%s+%08x+%s", name, id,
		base64.StdEncoding.EncodeToString(append([]byte{1}, seed...)))
	return skey, vkey, nil
}

func signNote(r signRequest) signAnswer {
	var skey, vkey string
	var err error
	if len(r.Seed) == 0 {
		skey, vkey, err = note.GenerateKey(nil, r.Name)
	} else {
		skey, vkey, err = signerKey(r.Name, r.Seed)
	}
	if err != nil {
		return signAnswer{Error: err.Error()}
	}
	signer, err := note.NewSigner(skey)
	if err != nil {
		return signAnswer{Error: err.Error()}
	}
	msg, err := note.Sign(&note.Note{Text: r.Text}, signer)
	if err != nil {
		return signAnswer{Error: err.Error()}
	}
	return signAnswer{Note: string(msg), Vkey: vkey}
}

func run(req request) (answer, error) {
	var a answer
	for _, o := range req.Open {
		a.Open = append(a.Open, openNote(o))
	}
	for _, s := range req.Sign {
		a.Sign = append(a.Sign, signNote(s))
	}

	var stored []tlog.Hash
	reader := tlog.HashReaderFunc(func(indexes []int64) ([]tlog.Hash, error) {
		out := make([]tlog.Hash, len(indexes))
		for i, x := range indexes {
			if x < 0 || x >= int64(len(stored)) {
				return nil, fmt.Errorf("no stored hash %d", x)
			}
			out[i] = stored[x]
		}
		return out, nil
	})
	for i, data := range req.Leaves {
		h := tlog.RecordHash(data)
		a.RecordHash = append(a.RecordHash, h[:])
		more, err := tlog.StoredHashes(int64(i), data, reader)
		if err != nil {
			return a, err
		}
		stored = append(stored, more...)
	}
	for _, n := range req.Roots {
		h, err := tlog.TreeHash(n, reader)
		if err != nil {
			return a, err
		}
		a.Roots = append(a.Roots, h[:])
	}
	a.Records = []string{}
	for _, c := range req.Records {
		a.Records = append(a.Records, checkRecord(c, req.Leaves))
	}
	a.Trees = []string{}
	for _, c := range req.Trees {
		a.Trees = append(a.Trees, checkTree(c))
	}
	a.ProveRecord = [][][]byte{}
	for _, st := range req.Prove {
		p, err := tlog.ProveRecord(st[0], st[1], reader)
		if err != nil {
			return a, err
		}
		a.ProveRecord = append(a.ProveRecord, hashBytes(p))
	}
	a.ProveTree = [][][]byte{}
	for _, on := range req.ProveOld {
		p, err := tlog.ProveTree(on[1], on[0], reader)
		if err != nil {
			return a, err
		}
		a.ProveTree = append(a.ProveTree, hashBytes(p))
	}
	if len(req.NodePair) == 2 {
		l, err1 := toHash(req.NodePair[0])
		r, err2 := toHash(req.NodePair[1])
		if err1 != nil || err2 != nil {
			return a, fmt.Errorf("node_pair holds two 32-byte hashes")
		}
		h := tlog.NodeHash(l, r)
		a.NodeHash = h[:]
	}
	return a, nil
}

func checkRecord(c recordCheck, leaves [][]byte) string {
	proof, err := toHashes(c.Proof)
	if err != nil {
		return err.Error()
	}
	root, err := toHash(c.Root)
	if err != nil {
		return err.Error()
	}
	if c.Index < 0 || c.Index >= int64(len(leaves)) {
		return "index beyond the leaves sent"
	}
	err = tlog.CheckRecord(tlog.RecordProof(proof), c.Size, root, c.Index, tlog.RecordHash(leaves[c.Index]))
	if err != nil {
		return err.Error()
	}
	return ""
}

func checkTree(c treeCheck) string {
	proof, err := toHashes(c.Proof)
	if err != nil {
		return err.Error()
	}
	oldRoot, err1 := toHash(c.OldRoot)
	newRoot, err2 := toHash(c.NewRoot)
	if err1 != nil || err2 != nil {
		return "roots are 32-byte hashes"
	}
	if err := tlog.CheckTree(tlog.TreeProof(proof), c.New, newRoot, c.Old, oldRoot); err != nil {
		return err.Error()
	}
	return ""
}

func main() {
	var req request
	dec := json.NewDecoder(os.Stdin)
	if err := dec.Decode(&req); err != nil {
		fmt.Fprintln(os.Stderr, "oracle: bad request:", err)
		os.Exit(2)
	}
	a, err := run(req)
	if err != nil {
		fmt.Fprintln(os.Stderr, "oracle:", err)
		os.Exit(1)
	}
	if err := json.NewEncoder(os.Stdout).Encode(a); err != nil {
		fmt.Fprintln(os.Stderr, "oracle:", err)
		os.Exit(1)
	}
}
